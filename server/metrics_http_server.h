// `serve --metrics-listen HOST:PORT`: a small HTTP server beside gRPC with
// Prometheus' text format at /metrics and a status page at / (status_page.h),
// both built from a MetricsSnapshot taken at each request. It has no token and
// no TLS of its own: bind it to loopback or to a network only the scraper
// reaches (docs/SERVING.md).
//
// Thread-safety: start() and the destructor from one thread; requests are
// served by two threads of its own, which call `collect` (it must be
// thread-safe) and read the ThroughputHistory.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/util/status.h"
#include "server/metrics_snapshot.h"
#include "server/throughput_history.h"

namespace httplib {
class Server;
}

namespace outcore::server {

class MetricsHttpServer {
 public:
  using Collect = std::function<MetricsSnapshot()>;

  // Listens on `host_port` (port 0: any free one) and serves until
  // destroyed. INVALID_ARGUMENT naming --metrics-listen when the address
  // does not parse, IO_ERROR when it cannot be bound.
  static Expected<std::unique_ptr<MetricsHttpServer>> start(const std::string& host_port, Collect collect,
                                                            ServerIdentity identity,
                                                            const ThroughputHistory& history);
  ~MetricsHttpServer();
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  // "HOST:PORT" with the port bound.
  const std::string& address() const { return address_; }

 private:
  MetricsHttpServer() = default;

  std::unique_ptr<httplib::Server> http_;
  std::thread thread_;
  std::string address_;
};

}  // namespace outcore::server
