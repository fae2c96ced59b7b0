// The server's observability pieces on their own: calls counted by method and
// code with a duration histogram (rpc_metrics.h), the Prometheus text they
// render (metrics_snapshot.h), recent throughput (throughput_history.h), the
// status page's escaping (status_page.h), JSON log lines
// (json_log_formatter.h) and the listen-address rule (server_security.h).
// The endpoint itself is scraped end to end in tests/python/test_service.py.
#include <gtest/gtest.h>
#include <spdlog/details/log_msg.h>

#include <map>
#include <regex>
#include <sstream>
#include <string>

#include "server/json_log_formatter.h"
#include "server/metrics_snapshot.h"
#include "server/rpc_metrics.h"
#include "server/server_security.h"
#include "server/status_page.h"
#include "server/throughput_history.h"

namespace outcore::server {
namespace OUTCORE_UNITY_ID {

// name{labels} -> value for every sample line; fails the test on a line that
// is not a HELP/TYPE comment or a well-formed sample.
std::map<std::string, double> parse_samples(const std::string& text) {
  static const std::regex sample(R"(^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{.*\})? (\S+)$)");
  std::map<std::string, double> samples;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.rfind("# HELP ", 0) == 0 || line.rfind("# TYPE ", 0) == 0) continue;
    std::smatch match;
    EXPECT_TRUE(std::regex_match(line, match, sample)) << line;
    if (match.empty()) continue;
    const std::string value = match[3];
    samples[match[1].str() + match[2].str()] = value == "+Inf" ? INFINITY : std::stod(value);
  }
  return samples;
}

TEST(RpcMetrics, CountsByMethodAndCodeWithBucketsOnTheirUpperBound) {
  RpcMetrics metrics;
  metrics.observe("/outcore.v1.SceneQuery/Intersect", 0, 0.0005);  // on the first bound: its bucket
  metrics.observe("/outcore.v1.SceneQuery/Intersect", 0, 0.003);
  metrics.observe("/outcore.v1.SceneQuery/Intersect", 3, 100.0);  // above every bound
  metrics.observe("/grpc.health.v1.Health/Check", 16, 0.0001);
  const auto figures = metrics.snapshot();
  ASSERT_EQ(figures.size(), 2u);
  const MethodFigures& intersect = figures[1];
  EXPECT_EQ(intersect.method, "outcore.v1.SceneQuery/Intersect");
  EXPECT_EQ(intersect.calls, 3u);
  EXPECT_EQ(intersect.by_code.at("OK"), 2u);
  EXPECT_EQ(intersect.by_code.at("INVALID_ARGUMENT"), 1u);
  EXPECT_EQ(intersect.buckets[0], 1u);
  EXPECT_EQ(intersect.buckets[3], 1u);  // (0.0025, 0.005]
  EXPECT_EQ(intersect.buckets.back(), 1u);
  EXPECT_DOUBLE_EQ(intersect.seconds_sum, 0.0005 + 0.003 + 100.0);
  EXPECT_EQ(figures[0].by_code.at("UNAUTHENTICATED"), 1u);
}

TEST(RpcMetrics, BoundsTheMethodLabels) {
  RpcMetrics metrics;
  for (std::size_t i = 0; i < kMaxMethodLabels + 10; ++i)
    metrics.observe("/x/m" + std::to_string(i), 12, 0.01);
  const auto figures = metrics.snapshot();
  EXPECT_EQ(figures.size(), kMaxMethodLabels + 1);  // the first 64 and "other"
  uint64_t other = 0;
  for (const MethodFigures& m : figures) {
    if (m.method == kOtherMethodLabel) other = m.calls;
  }
  EXPECT_EQ(other, 10u);
}

TEST(PrometheusText, RendersEveryFamilyWithCumulativeHistogramAndEscapedLabels) {
  RpcMetrics metrics;
  metrics.observe("/outcore.v1.SceneQuery/Intersect", 0, 0.002);
  metrics.observe("/outcore.v1.SceneQuery/Intersect", 0, 0.2);
  MetricsSnapshot snapshot;
  snapshot.rpcs = metrics.snapshot();
  snapshot.service.answered.rays = 123456789;
  snapshot.service.answered.rays_hit = 1000;
  snapshot.cache.builds = 7;
  snapshot.cache.hits = 40;
  snapshot.cache.misses = 7;
  snapshot.cache.evictions = 2;
  snapshot.cache.resident_bytes = 1 << 20;
  snapshot.cache.subtree.loads = 3;
  snapshot.cache_budget_bytes = 4 << 20;
  ServerIdentity identity;
  identity.scene = "/scenes/a \"quoted\"\\path\nx";
  const std::string text = prometheus_text(snapshot, identity);
  const auto samples = parse_samples(text);
  EXPECT_EQ(samples.at("outcore_rays_total"), 123456789);
  EXPECT_EQ(samples.at("outcore_brick_builds_total"), 7);
  EXPECT_EQ(samples.at("outcore_cache_hits_total"), 40);
  EXPECT_EQ(samples.at("outcore_cache_misses_total"), 7);
  EXPECT_EQ(samples.at("outcore_cache_evictions_total"), 2);
  EXPECT_EQ(samples.at("outcore_cache_resident_bytes"), 1 << 20);
  EXPECT_EQ(samples.at("outcore_cache_budget_bytes"), 4 << 20);
  EXPECT_EQ(samples.at("outcore_subtree_loads_total"), 3);
  const std::string method = "method=\"outcore.v1.SceneQuery/Intersect\"";
  EXPECT_EQ(samples.at("outcore_requests_total{" + method + ",code=\"OK\"}"), 2);
  EXPECT_EQ(samples.at("outcore_request_seconds_bucket{" + method + ",le=\"0.001\"}"), 0);
  EXPECT_EQ(samples.at("outcore_request_seconds_bucket{" + method + ",le=\"0.0025\"}"), 1);
  EXPECT_EQ(samples.at("outcore_request_seconds_bucket{" + method + ",le=\"0.25\"}"), 2);
  EXPECT_EQ(samples.at("outcore_request_seconds_bucket{" + method + ",le=\"+Inf\"}"), 2);
  EXPECT_EQ(samples.at("outcore_request_seconds_count{" + method + "}"), 2);
  EXPECT_DOUBLE_EQ(samples.at("outcore_request_seconds_sum{" + method + "}"), 0.202);
  EXPECT_NE(text.find("scene=\"/scenes/a \\\"quoted\\\"\\\\path\\nx\""), std::string::npos);
  // Each family declared once, before its samples.
  EXPECT_EQ(text.find("# TYPE outcore_request_seconds histogram"),
            text.rfind("# TYPE outcore_request_seconds histogram"));
  EXPECT_LT(text.find("# TYPE outcore_rays_total counter"), text.find("\noutcore_rays_total "));
}

TEST(ThroughputHistory, RateOverTheWindowFromTheSamples) {
  ThroughputHistory history;
  const auto t0 = ThroughputHistory::Clock::time_point{} + std::chrono::hours(1);
  EXPECT_EQ(history.rays_per_second(std::chrono::seconds(10)), 0);
  for (int s = 0; s <= 60; ++s) {
    // 1000 rays/s for the first 50 s, then 10000 rays/s.
    const uint64_t rays = s <= 50 ? 1000ull * s : 50000ull + 10000ull * (s - 50);
    history.record(t0 + std::chrono::seconds(s), rays);
  }
  EXPECT_DOUBLE_EQ(history.rays_per_second(std::chrono::seconds(10)), 10000);
  EXPECT_DOUBLE_EQ(history.rays_per_second(std::chrono::seconds(60)), (150000.0 - 0) / 60);
  EXPECT_DOUBLE_EQ(history.rays_per_second(std::chrono::seconds(600)), 150000.0 / 60);  // the oldest kept
}

TEST(StatusPage, EscapesWhatItShows) {
  ServerIdentity identity;
  identity.scene = "<script>alert('x')</script>&";
  RpcMetrics metrics;
  metrics.observe("/a<b>/c", 0, 0.01);
  MetricsSnapshot snapshot;
  snapshot.rpcs = metrics.snapshot();
  snapshot.cache_budget_bytes = 100;
  snapshot.cache.resident_bytes = 25;
  const std::string html = status_page_html(snapshot, identity, RecentThroughput{1500, 1200});
  EXPECT_EQ(html.find("<script>"), std::string::npos);
  EXPECT_NE(html.find("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;&amp;"), std::string::npos);
  EXPECT_NE(html.find("a&lt;b&gt;/c"), std::string::npos);
  EXPECT_NE(html.find("25.0 %"), std::string::npos);
}

TEST(JsonLogFormatter, OneEscapedObjectPerLine) {
  JsonLogFormatter formatter;
  const spdlog::details::log_msg msg("outcore-serve", spdlog::level::warn, "path \"a\\b\"\n\tbell\x07 é");
  spdlog::memory_buf_t out;
  formatter.format(msg, out);
  const std::string line(out.data(), out.size());
  static const std::regex shape(
      R"re(^\{"time":"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z","level":"warning","logger":"outcore-serve","message":"(.*)"\}\n$)re");
  std::smatch match;
  ASSERT_TRUE(std::regex_match(line, match, shape)) << line;
  EXPECT_EQ(match[1].str(), "path \\\"a\\\\b\\\"\\n\\tbell\\u0007 é");
  EXPECT_EQ(std::count(line.begin(), line.end(), '\n'), 1);
}

TEST(ListenExposure, PlaintextOnlyOnLoopbackUnlessAskedFor) {
  for (const char* loopback : {"127.0.0.1:50051", "127.3.4.5:0", "[::1]:50051", "localhost:50051",
                               "LocalHost.:50051", "unix:/tmp/outcore.sock"}) {
    EXPECT_TRUE(check_listen_exposure(loopback, false, false).ok()) << loopback;
  }
  for (const char* exposed : {"0.0.0.0:50051", "[::]:50051", "10.1.2.3:50051", "myhost:50051"}) {
    const Status refused = check_listen_exposure(exposed, false, false);
    ASSERT_FALSE(refused.ok()) << exposed;
    EXPECT_NE(refused.message().find("--tls-cert"), std::string::npos);
    EXPECT_NE(refused.message().find("--insecure"), std::string::npos);
    EXPECT_TRUE(check_listen_exposure(exposed, true, false).ok());
    EXPECT_TRUE(check_listen_exposure(exposed, false, true).ok());
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore::server
