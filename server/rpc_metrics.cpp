#include "server/rpc_metrics.h"

#include <grpcpp/support/status.h>

#include <algorithm>
#include <chrono>

#include "proto/outcore/v1/grpc_code_names.h"

namespace outcore::server {

namespace {

using Clock = std::chrono::steady_clock;

class RpcMetricsInterceptor final : public grpc::experimental::Interceptor {
 public:
  RpcMetricsInterceptor(RpcMetrics& metrics, const char* method)
      : metrics_(metrics), method_(method != nullptr ? method : ""), start_(Clock::now()) {}

  ~RpcMetricsInterceptor() override {
    // A call torn down without a status sent (the client went away first).
    if (!observed_) observe(grpc::StatusCode::CANCELLED);
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (!observed_ &&
        methods->QueryInterceptionHookPoint(grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      observe(methods->GetSendStatus().error_code());
    }
    methods->Proceed();
  }

 private:
  void observe(int code) {
    observed_ = true;
    metrics_.observe(method_, code, std::chrono::duration<double>(Clock::now() - start_).count());
  }

  RpcMetrics& metrics_;
  std::string_view method_;  // gRPC's method name outlives the call
  Clock::time_point start_;
  bool observed_ = false;
};

}  // namespace

void RpcMetrics::observe(std::string_view method, int status_code, double seconds) {
  if (method.starts_with('/')) method.remove_prefix(1);
  const auto bucket = static_cast<std::size_t>(
      std::lower_bound(kRequestSecondsBuckets.begin(), kRequestSecondsBuckets.end(), seconds) -
      kRequestSecondsBuckets.begin());
  const std::string code = wire::grpc_code_name(static_cast<grpc::StatusCode>(status_code));
  std::lock_guard lock(mutex_);
  auto it = methods_.find(method);
  if (it == methods_.end()) {
    if (methods_.size() >= kMaxMethodLabels) method = kOtherMethodLabel;
    it = methods_.try_emplace(std::string(method)).first;
    it->second.method = std::string(method);
  }
  MethodFigures& figures = it->second;
  ++figures.by_code[code];
  ++figures.buckets[bucket];
  figures.seconds_sum += seconds;
  ++figures.calls;
}

std::vector<MethodFigures> RpcMetrics::snapshot() const {
  std::lock_guard lock(mutex_);
  std::vector<MethodFigures> figures;
  figures.reserve(methods_.size());
  for (const auto& [name, method] : methods_) figures.push_back(method);
  return figures;
}

grpc::experimental::Interceptor* RpcMetricsInterceptorFactory::CreateServerInterceptor(
    grpc::experimental::ServerRpcInfo* info) {
  return new RpcMetricsInterceptor(metrics_, info->method());
}

}  // namespace outcore::server
