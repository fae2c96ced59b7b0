// RpcMetrics: every call the gRPC server ends, counted by method and status
// code, and its duration in a histogram per method, for the Prometheus
// endpoint (metrics_http_server.h). Filled by a server interceptor
// (RpcMetricsInterceptorFactory) so that every method — health checks,
// reflection and calls refused before a handler ran included — is counted in
// one place, without each handler taking part.
//
// Thread-safety: observe() and snapshot() may be called from any thread. A
// call takes one short mutex when it ends (never per ray); the labels are
// bounded (kMaxMethodLabels), so a client inventing method names cannot grow
// the registry without end.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

namespace outcore::server {

// Upper bounds (seconds) of the request duration histogram's buckets; the
// +Inf bucket is implied. From a health check (~0.1 ms) to a 1 M-ray batch
// out of core (seconds).
inline constexpr std::array<double, 14> kRequestSecondsBuckets = {
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 10, 60};

// Distinct method labels kept; calls to further (unknown) methods are
// counted under kOtherMethodLabel.
inline constexpr std::size_t kMaxMethodLabels = 64;
inline constexpr std::string_view kOtherMethodLabel = "other";

struct MethodFigures {
  std::string method;                       // "outcore.v1.SceneQuery/Intersect"
  std::map<std::string, uint64_t> by_code;  // "OK", "UNAUTHENTICATED", ...
  // Calls whose duration was <= kRequestSecondsBuckets[i] (not cumulative);
  // the last slot is those above every bound.
  std::array<uint64_t, kRequestSecondsBuckets.size() + 1> buckets{};
  double seconds_sum = 0;
  uint64_t calls = 0;
};

class RpcMetrics {
 public:
  // One call ended. `method` is gRPC's "/package.Service/Method".
  void observe(std::string_view method, int status_code, double seconds);
  // Every method seen so far, by name.
  std::vector<MethodFigures> snapshot() const;

 private:
  mutable std::mutex mutex_;
  std::map<std::string, MethodFigures, std::less<>> methods_;
};

// Gives each call an interceptor that observes it in `metrics` when its
// status is sent (or, should it never be, as CANCELLED when the call ends).
class RpcMetricsInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit RpcMetricsInterceptorFactory(RpcMetrics& metrics) : metrics_(metrics) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;

 private:
  RpcMetrics& metrics_;
};

}  // namespace outcore::server
