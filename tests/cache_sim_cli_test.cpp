// End-to-end tests of the cache-tuning workflow, run as the real binary:
// `outcore trace --trace-out` records every brick request; `outcore cache-sim`
// replays it against every policy and budget next to Belady's OPT, and its
// replay of the recorded policy at the recorded budget reproduces the live
// run's builds exactly; --json, --png and the errors that name what is wrong.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "core/cache/access_trace.h"
#include "core/io/npy.h"
#include "core/ray/ray_types.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::SubprocessResult;
using testing::TempDir;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(120'000));
}

// The value of the first `"key": number` at or after the n-th "policy": "name".
double json_number_for(const std::string& json, const std::string& policy, const std::string& key,
                       int nth = 0) {
  std::size_t at = 0;
  for (int i = 0; i <= nth; ++i) {
    at = json.find("\"policy\":\"" + policy + "\"", at == 0 ? 0 : at + 1);
    if (at == std::string::npos) return -1;
  }
  const std::regex number("\"" + key + "\":([-0-9.eE+]+)");
  std::smatch m;
  const std::string rest = json.substr(at);
  if (!std::regex_search(rest, m, number)) return -1;
  return std::stod(m[1]);
}

class CacheSimCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    const SubprocessResult packed = outcore(
        {"pack", "gen:sphere?level=5", "-o", dir_->file("scene"), "--brick-tris", "512", "-q", "--no-sync"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<Ray> rays(2000);
    for (Ray& ray : rays) {
      ray.origin = {3.0f * u(rng), 3.0f * u(rng), 3.0f};
      ray.direction = Vec3f{u(rng), u(rng), u(rng)} - ray.origin;
    }
    ASSERT_TRUE(write_rays_npy(dir_->file("rays.npy"), rays).ok());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string file(const std::string& name) { return dir_->file(name); }
  static TempDir* dir_;
};
TempDir* CacheSimCliTest::dir_ = nullptr;

TEST_F(CacheSimCliTest, TraceOutThenReplayReproducesTheLiveBuilds) {
  // 1 MiB holds only part of the scene: evictions and rebuilds over 3 runs
  // (the later runs warm but still too small).
  const SubprocessResult traced =
      outcore({"trace", file("scene"), "--rays", file("rays.npy"), "-o", file("hits.npy"), "--cache-mb", "1",
               "--policy", "arc", "--no-reorder", "--repeat", "2", "--trace-out", file("arc.csv"),
               "--stats-json", file("stats.json")});
  ASSERT_TRUE(traced.succeeded()) << traced.describe();
  auto trace = read_access_trace(file("arc.csv"));
  ASSERT_TRUE(trace.ok()) << trace.status().to_string();
  EXPECT_EQ(trace->info.policy, "arc");
  EXPECT_EQ(trace->info.budget_bytes, uint64_t{1} << 20);
  EXPECT_TRUE(contains(trace->info.source, "rays.npy")) << trace->info.source;
  uint64_t misses = 0;
  for (const AccessRecord& r : trace->records) misses += r.outcome != AccessOutcome::kHit;
  std::ifstream stats_in(file("stats.json"));
  const std::string stats((std::istreambuf_iterator<char>(stats_in)), std::istreambuf_iterator<char>());
  // --repeat 2 writes an array of two runs' statistics: sum them.
  const auto sum_of = [&](const std::string& key) {
    uint64_t sum = 0;
    const std::regex re("\"" + key + "\":([0-9]+)");
    for (auto it = std::sregex_iterator(stats.begin(), stats.end(), re); it != std::sregex_iterator(); ++it)
      sum += std::stoull((*it)[1]);
    return sum;
  };
  const uint64_t live_builds = sum_of("brick_builds");
  const uint64_t live_acquisitions = sum_of("brick_acquisitions");
  EXPECT_EQ(trace->records.size(), live_acquisitions);
  EXPECT_EQ(misses, live_builds);
  ASSERT_LT(live_builds, live_acquisitions) << "expected some hits";

  const SubprocessResult sim = outcore({"cache-sim", file("arc.csv"), "--policy", "all", "--budget-mb",
                                        "1,2,8", "--json", "--png", file("plot.png")});
  ASSERT_TRUE(sim.succeeded()) << sim.describe();
  const std::string& json = sim.stdout_text;
  EXPECT_EQ(json_number_for(json, "arc", "budget_bytes"), 1048576.0) << json;
  EXPECT_EQ(json_number_for(json, "arc", "misses"), static_cast<double>(live_builds)) << json;
  for (const std::string policy : {"lru", "clock", "lfu", "arc", "s3fifo", "gdsf", "opt"}) {
    for (int budget = 0; budget < 3; ++budget) {
      const double m = json_number_for(json, policy, "misses", budget);
      EXPECT_GE(m, json_number_for(json, "opt", "misses", budget)) << policy << " beat OPT";
    }
  }
  std::ifstream png(file("plot.png"), std::ios::binary);
  char signature[8] = {};
  png.read(signature, 8);
  EXPECT_EQ(std::memcmp(signature, "\x89PNG\r\n\x1a\n", 8), 0);
}

TEST_F(CacheSimCliTest, PrintsATableWithEveryPolicyAndOpt) {
  const SubprocessResult traced =
      outcore({"trace", file("scene"), "--rays", file("rays.npy"), "-o", file("hits2.npy"), "--cache-mb", "2",
               "--trace-out", file("lru.csv")});
  ASSERT_TRUE(traced.succeeded()) << traced.describe();
  const SubprocessResult sim = outcore({"cache-sim", file("lru.csv"), "--budget-fractions", "0.5,1"});
  ASSERT_TRUE(sim.succeeded()) << sim.describe();
  for (const std::string word : {"budget_MiB", "miss_ratio", "built_MiB", "build_s", "vs_opt", "lru", "clock",
                                 "lfu", "arc", "s3fifo", "gdsf", "opt", "recorded with lru at 2.00 MiB"})
    EXPECT_TRUE(contains(sim.stdout_text, word)) << word << "\n" << sim.stdout_text;
}

TEST_F(CacheSimCliTest, ErrorsNameWhatIsWrong) {
  const std::string trace = file("errors.csv");
  {
    std::ofstream out(trace);
    out << "# outcore brick access trace, version 1\n"
           "seq,brick,bytes,reserved_bytes,build_seconds,outcome\n"
           "0,3,1000,4000000,0.01,miss\n"
           "1,3,1000,4000000,0,hit\n";
  }
  struct Case {
    std::vector<std::string> args;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {{"cache-sim", file("nope.csv")}, "nope.csv"},
      {{"cache-sim", trace, "--policy", "mru"}, "unknown eviction policy 'mru' (known: lru, clock, lfu, arc"},
      {{"cache-sim", trace, "--budget-mb", "1"}, "brick 3 (trace record 0) needs up to 3.81 MiB"},
      {{"cache-sim", trace, "--budget-mb", "1", "--budget-fractions", "0.5"}, "not both"},
      {{"cache-sim", trace, "--budget-mb", "1,x"}, "--budget-mb 'x' is not a positive number"},
      {{"cache-sim", trace, "--budget-fractions", "-1"}, "--budget-fractions '-1' is not a positive number"},
  };
  for (const Case& c : cases) {
    const SubprocessResult r = outcore(c.args);
    EXPECT_EQ(r.exit_code, 1) << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, c.expected)) << r.stderr_text << "\nwanted: " << c.expected;
  }
  // Default fractions below the largest brick are skipped with a note.
  const SubprocessResult r = outcore({"cache-sim", trace});
  EXPECT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "skipping budget fraction")) << r.stderr_text;
}

// Issue 21, finding 9: byte counts near 2^63 wrapped the replay's sums (an
// empty or nonsense table, exit 0). Each is now an error naming the line and
// the value; budgets that would overflow name the option and value; and a
// trace at the edge of the limit still replays with the right figures.
TEST_F(CacheSimCliTest, HugeByteCountsAreErrorsNamingTheLineAndValue) {
  const auto write_trace = [&](const std::string& name, const std::string& records) {
    std::ofstream out(file(name));
    out << "# outcore brick access trace, version 2\n"
           "seq,brick,bytes,reserved_bytes,build_seconds,outcome\n"
        << records;
    return file(name);
  };
  const std::string two63 = "9223372036854775808";  // 2^63
  struct Case {
    std::vector<std::string> args;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {{"cache-sim", write_trace("huge.csv", "0,1," + two63 + ",0,0.5,miss\n")},
       "huge.csv:3: bytes " + two63 + " is more than 4611686018427387904 (2^62)"},
      {{"cache-sim", write_trace("huge_reserve.csv", "0,1,100,18446744073709551615,0.5,miss\n")},
       "huge_reserve.csv:3: reserved_bytes 18446744073709551615 is more than"},
      // Two bricks of just over 2^61 bytes: the sum passes 2^62 at the second record.
      {{"cache-sim",
        write_trace("sum.csv", "0,0,2305843009213693952,0,0.5,miss\n1,1,2305843009213693953,0,0.5,miss\n")},
       "sum.csv:4: bytes 2305843009213693953 brings the trace's byte counts to more than "
       "4611686018427387904"},
      {{"cache-sim", write_trace("small.csv", "0,0,1000,0,0.5,miss\n"), "--budget-mb", "1e300"},
       "--budget-mb 1e+300 is more than 4.39805e+12 MiB"},
      {{"cache-sim", file("small.csv"), "--budget-mb", "1e-12"}, "--budget-mb 1e-12 is less than one byte"},
      {{"cache-sim", file("small.csv"), "--budget-fractions", "1e16"},
       "--budget-fractions 1e+16 of the working set (1000 bytes) is more than 2^62 bytes"},
  };
  for (const Case& c : cases) {
    const SubprocessResult r = outcore(c.args);
    EXPECT_EQ(r.exit_code, 1) << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, c.expected)) << r.stderr_text << "\nwanted: " << c.expected;
    EXPECT_FALSE(contains(r.stdout_text, "budget_MiB")) << "no table on an error\n" << r.stdout_text;
  }

  // 2^60-byte bricks (four fit under the limit with their reservations):
  // sums of them are exact, so a budget of one brick misses every request of
  // an alternating trace and a budget of two misses only the first two.
  const std::string edge = write_trace("edge.csv",
                                       "0,0,1152921504606846976,0,1,miss\n"
                                       "1,1,1152921504606846976,0,1,miss\n"
                                       "2,0,1152921504606846976,0,0,hit\n"
                                       "3,1,1152921504606846976,0,0,hit\n");
  const SubprocessResult r =
      outcore({"cache-sim", edge, "--policy", "lru", "--budget-fractions", "0.5,1", "--json"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_EQ(json_number_for(r.stdout_text, "lru", "misses", 0), 4) << r.stdout_text;
  EXPECT_EQ(json_number_for(r.stdout_text, "lru", "misses", 1), 2) << r.stdout_text;
  EXPECT_EQ(json_number_for(r.stdout_text, "lru", "budget_bytes", 1), 2305843009213693952.0) << r.stdout_text;
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
