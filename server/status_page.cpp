#include "server/status_page.h"

#include <cstdio>

#include "core/util/progress.h"

namespace outcore::server {

namespace {

std::string row(const std::string& name, const std::string& value) {
  return "<tr><th>" + escape_html(name) + "</th><td>" + escape_html(value) + "</td></tr>\n";
}

std::string fixed(double value, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", digits, value);
  return buffer;
}

std::string calls_table(const std::vector<MethodFigures>& rpcs) {
  std::string html =
      "<h2>Calls</h2>\n<table>\n<tr><th>method</th><th>calls</th><th>by code</th><th>mean ms</th></tr>\n";
  for (const MethodFigures& m : rpcs) {
    std::string codes;
    for (const auto& [code, count] : m.by_code) {
      if (!codes.empty()) codes += ", ";
      codes += code + " " + std::to_string(count);
    }
    const double mean_ms = m.calls > 0 ? 1000.0 * m.seconds_sum / static_cast<double>(m.calls) : 0;
    html += "<tr><td>" + escape_html(m.method) + "</td><td>" + std::to_string(m.calls) + "</td><td>" +
            escape_html(codes) + "</td><td>" + fixed(mean_ms, 3) + "</td></tr>\n";
  }
  return html + "</table>\n";
}

}  // namespace

std::string escape_html(const std::string& text) {
  std::string escaped;
  escaped.reserve(text.size());
  for (const char ch : text) {
    switch (ch) {
      case '&': escaped += "&amp;"; break;
      case '<': escaped += "&lt;"; break;
      case '>': escaped += "&gt;"; break;
      case '"': escaped += "&quot;"; break;
      case '\'': escaped += "&#39;"; break;
      default: escaped += ch;
    }
  }
  return escaped;
}

std::string status_page_html(const MetricsSnapshot& snapshot, const ServerIdentity& identity,
                             const RecentThroughput& recent) {
  const CacheCounters& cache = snapshot.cache;
  const double fill = snapshot.cache_budget_bytes > 0 ? 100.0 * static_cast<double>(cache.resident_bytes) /
                                                            static_cast<double>(snapshot.cache_budget_bytes)
                                                      : 0;
  const uint64_t acquisitions = cache.hits + cache.misses;
  const double hit_rate =
      acquisitions > 0 ? 100.0 * static_cast<double>(cache.hits) / static_cast<double>(acquisitions) : 0;
  std::string html =
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><meta http-equiv=\"refresh\" content=\"5\">"
      "<title>outcore serve</title><style>body{font-family:sans-serif;margin:2em}"
      "th{text-align:left;padding-right:1.5em}td{padding-right:1.5em}</style></head><body>\n"
      "<h1>outcore serve</h1>\n<h2>Scene</h2>\n<table>\n";
  html += row("store", identity.scene);
  html += row("listening on", identity.address + (identity.tls ? " (TLS)" : " (plaintext)") +
                                  (identity.token ? ", bearer token required" : ""));
  html += row("triangles", human_count(static_cast<double>(identity.triangles)));
  html += row("bricks", std::to_string(identity.bricks));
  html += row("brick structure", identity.brick_structure);
  html += row("version", identity.version);
  html += row("uptime", fixed(snapshot.uptime_seconds, 0) + " s");
  html += "</table>\n<h2>Cache</h2>\n<table>\n";
  html += row("policy", identity.eviction_policy);
  html += row("fill", human_bytes(static_cast<double>(cache.resident_bytes)) + " of " +
                          human_bytes(static_cast<double>(snapshot.cache_budget_bytes)) + " (" +
                          fixed(fill, 1) + " %), " + std::to_string(cache.resident_bricks) + " bricks");
  html += row("hits / misses", std::to_string(cache.hits) + " / " + std::to_string(cache.misses) + " (" +
                                   fixed(hit_rate, 1) + " % hits)");
  html += row("builds / evictions", std::to_string(cache.builds) + " / " + std::to_string(cache.evictions));
  html += row("subtree loads", std::to_string(cache.subtree.loads));
  html += "</table>\n<h2>Throughput</h2>\n<table>\n";
  html += row("rays answered", std::to_string(snapshot.service.answered.rays));
  html += row("last 10 s", human_count(recent.rays_per_second_10s) + " rays/s");
  html += row("last 60 s", human_count(recent.rays_per_second_60s) + " rays/s");
  html += row("requests (failed)", std::to_string(snapshot.service.requests) + " (" +
                                       std::to_string(snapshot.service.failed_requests) + ")");
  html += "</table>\n";
  html += calls_table(snapshot.rpcs);
  html += "<p><a href=\"/metrics\">/metrics</a> (Prometheus)</p>\n</body></html>\n";
  return html;
}

}  // namespace outcore::server
