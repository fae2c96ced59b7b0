// The metrics server's HTML status page (GET /): the scene, the cache's fill
// and policy, recent throughput and the calls by method, for a person
// looking at a running server. Refreshes itself every 5 seconds.
//
// Thread-safety: a pure function.
#pragma once

#include <string>

#include "server/metrics_snapshot.h"

namespace outcore::server {

struct RecentThroughput {
  double rays_per_second_10s = 0;
  double rays_per_second_60s = 0;
};

std::string status_page_html(const MetricsSnapshot& snapshot, const ServerIdentity& identity,
                             const RecentThroughput& recent);

// `text` with &, <, >, " and ' escaped for HTML.
std::string escape_html(const std::string& text);

}  // namespace outcore::server
