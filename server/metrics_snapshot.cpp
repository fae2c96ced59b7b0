#include "server/metrics_snapshot.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/query/query_engine.h"
#include "server/scene_query_service.h"

namespace outcore::server {

namespace {

// Appends metric families in the text format: a HELP and TYPE line once per
// family, then its samples.
class ExpositionWriter {
 public:
  void family(const char* name, const char* type, const char* help) {
    text_ += "# HELP ";
    text_ += name;
    text_ += ' ';
    text_ += help;
    text_ += "\n# TYPE ";
    text_ += name;
    text_ += ' ';
    text_ += type;
    text_ += '\n';
  }
  // `labels` is "" or the inside of {...}, already escaped.
  void sample(const std::string& name, const std::string& labels, double value) {
    text_ += name;
    if (!labels.empty()) {
      text_ += '{';
      text_ += labels;
      text_ += '}';
    }
    text_ += ' ';
    text_ += number(value);
    text_ += '\n';
  }
  void single(const char* name, const char* type, const char* help, double value) {
    family(name, type, help);
    sample(name, "", value);
  }
  std::string take() { return std::move(text_); }

  static std::string number(double value) {
    if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
    if (std::isnan(value)) return "NaN";
    // Counts print as integers.
    char buffer[40];
    if (value == std::floor(value) && std::fabs(value) < 1e18) {
      std::snprintf(buffer, sizeof buffer, "%.0f", value);
    } else {
      // The shortest of %.15g and %.17g that reads back as the same double
      // (bucket bounds print as 0.0025, not 0.0025000000000000001).
      std::snprintf(buffer, sizeof buffer, "%.15g", value);
      if (std::strtod(buffer, nullptr) != value) std::snprintf(buffer, sizeof buffer, "%.17g", value);
    }
    return buffer;
  }

 private:
  std::string text_;
};

std::string label(const char* name, const std::string& value) {
  return std::string(name) + "=\"" + escape_label_value(value) + "\"";
}

void write_rpcs(ExpositionWriter& out, const std::vector<MethodFigures>& rpcs) {
  out.family("outcore_requests_total", "counter",
             "Calls ended, by gRPC method and status code (health checks and refused calls included).");
  for (const MethodFigures& m : rpcs) {
    for (const auto& [code, count] : m.by_code) {
      out.sample("outcore_requests_total", label("method", m.method) + "," + label("code", code),
                 static_cast<double>(count));
    }
  }
  out.family("outcore_request_seconds", "histogram", "Duration of calls, from their start to their status.");
  for (const MethodFigures& m : rpcs) {
    const std::string method = label("method", m.method);
    uint64_t cumulative = 0;
    for (std::size_t i = 0; i < m.buckets.size(); ++i) {
      cumulative += m.buckets[i];
      const double bound = i < kRequestSecondsBuckets.size() ? kRequestSecondsBuckets[i] : INFINITY;
      out.sample("outcore_request_seconds_bucket",
                 method + "," + label("le", ExpositionWriter::number(bound)),
                 static_cast<double>(cumulative));
    }
    out.sample("outcore_request_seconds_sum", method, m.seconds_sum);
    out.sample("outcore_request_seconds_count", method, static_cast<double>(m.calls));
  }
}

void write_engine(ExpositionWriter& out, const MetricsSnapshot& s) {
  const QueryStats& a = s.service.answered;
  const CacheCounters& c = s.cache;
  const auto d = [](uint64_t v) { return static_cast<double>(v); };
  out.single("outcore_query_requests_total", "counter",
             "Query requests and stream chunks answered or refused by the service.", d(s.service.requests));
  out.single("outcore_query_requests_failed_total", "counter",
             "Of those, the ones that failed (cancelled included).", d(s.service.failed_requests));
  out.single("outcore_rays_total", "counter", "Rays (and points) answered.", d(a.rays));
  out.single("outcore_rays_hit_total", "counter", "Rays answered with a hit.", d(a.rays_hit));
  out.single("outcore_invalid_rays_total", "counter", "Invalid rays answered as misses.", d(a.invalid_rays));
  out.single("outcore_tracing_seconds_total", "counter", "Seconds the engine spent answering requests.",
             a.seconds_total);
  out.single("outcore_brick_builds_total", "counter", "Brick subtrees built into the cache.", d(c.builds));
  out.single("outcore_brick_rebuilds_total", "counter", "Bricks rebuilt as another structure.",
             d(c.rebuilds));
  out.single("outcore_brick_build_seconds_total", "counter", "Seconds spent loading and building bricks.",
             c.build_seconds);
  out.single("outcore_cache_hits_total", "counter", "Brick acquisitions that found the brick ready.",
             d(c.hits));
  out.single("outcore_cache_misses_total", "counter", "Brick acquisitions that built or waited for a build.",
             d(c.misses));
  out.single("outcore_cache_evictions_total", "counter", "Bricks evicted from the cache.", d(c.evictions));
  out.single("outcore_cache_resident_bytes", "gauge", "Bytes the cache holds (reservations included).",
             d(c.resident_bytes));
  out.single("outcore_cache_peak_resident_bytes", "gauge", "Most bytes the cache has held.",
             d(c.peak_resident_bytes));
  out.single("outcore_cache_budget_bytes", "gauge", "The cache's byte budget.", d(s.cache_budget_bytes));
  out.single("outcore_cache_resident_bricks", "gauge", "Bricks resident in the cache.", d(c.resident_bricks));
  out.single("outcore_subtree_loads_total", "counter", "Brick subtrees loaded from the subtree tier.",
             d(c.subtree.loads));
  out.single("outcore_subtree_writes_total", "counter", "Brick subtrees written to the subtree tier.",
             d(c.subtree.writes));
  out.single("outcore_dynamic_version", "gauge", "The dynamic layer's latest version.", d(s.dynamic_version));
  out.single("outcore_uptime_seconds", "gauge", "Seconds since the server started.", s.uptime_seconds);
}

}  // namespace

std::string escape_label_value(const std::string& value) {
  std::string escaped;
  escaped.reserve(value.size());
  for (const char ch : value) {
    if (ch == '\\') {
      escaped += "\\\\";
    } else if (ch == '"') {
      escaped += "\\\"";
    } else if (ch == '\n') {
      escaped += "\\n";
    } else {
      escaped += ch;
    }
  }
  return escaped;
}

MetricsSnapshot collect_metrics(const SceneQueryService& service, const QueryEngine& engine,
                                const RpcMetrics& rpcs, double uptime_seconds) {
  MetricsSnapshot snapshot;
  snapshot.service = service.counters();
  snapshot.cache = engine.cache().counters();
  snapshot.cache_budget_bytes = engine.cache().budget_bytes();
  snapshot.rpcs = rpcs.snapshot();
  if (const auto dynamic = engine.dynamic().latest()) snapshot.dynamic_version = dynamic->version;
  snapshot.uptime_seconds = uptime_seconds;
  return snapshot;
}

std::string prometheus_text(const MetricsSnapshot& snapshot, const ServerIdentity& identity) {
  ExpositionWriter out;
  out.family("outcore_info", "gauge", "The server's scene and configuration (value 1).");
  out.sample("outcore_info",
             label("version", identity.version) + "," + label("scene", identity.scene) + "," +
                 label("brick_structure", identity.brick_structure) + "," +
                 label("eviction_policy", identity.eviction_policy) + "," +
                 label("tls", identity.tls ? "true" : "false") + "," +
                 label("token", identity.token ? "true" : "false"),
             1);
  out.single("outcore_scene_triangles", "gauge", "Triangles in the served store.",
             static_cast<double>(identity.triangles));
  out.single("outcore_scene_bricks", "gauge", "Bricks in the served store.",
             static_cast<double>(identity.bricks));
  write_rpcs(out, snapshot.rpcs);
  write_engine(out, snapshot);
  return out.take();
}

}  // namespace outcore::server
