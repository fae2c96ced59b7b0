// MetricsSnapshot: the server's figures at one moment, as the metrics endpoint
// and the status page show them (metrics_http_server.h): the service's
// request and ray counts, the cache's, the calls by method and code
// (rpc_metrics.h); ServerIdentity is what does not change while serving.
// prometheus_text() renders them in Prometheus' text exposition format 0.0.4.
//
// Thread-safety: plain values and pure functions; collect_metrics reads
// thread-safe sources.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/cache/brick_cache.h"
#include "server/rpc_metrics.h"
#include "server/service_counters.h"

namespace outcore {
class QueryEngine;
}

namespace outcore::server {

class SceneQueryService;

struct ServerIdentity {
  std::string scene;            // the store's path as given to serve
  std::string address;          // where gRPC listens
  std::string brick_structure;  // --brick-accel
  std::string eviction_policy;
  uint64_t triangles = 0;
  uint32_t bricks = 0;
  bool tls = false;
  bool token = false;  // calls need the bearer token
  std::string version;
};

struct MetricsSnapshot {
  ServiceCounters service;
  CacheCounters cache;
  uint64_t cache_budget_bytes = 0;
  std::vector<MethodFigures> rpcs;
  uint64_t dynamic_version = 0;
  double uptime_seconds = 0;
};

MetricsSnapshot collect_metrics(const SceneQueryService& service, const QueryEngine& engine,
                                const RpcMetrics& rpcs, double uptime_seconds);

std::string prometheus_text(const MetricsSnapshot& snapshot, const ServerIdentity& identity);

// `value` with \, " and newlines escaped, as a Prometheus label value.
std::string escape_label_value(const std::string& value);

}  // namespace outcore::server
