// The simulator against hand-computed replays, and against the live cache: a
// real QueryEngine run with an access trace, replayed with the same policy and
// budget, gives exactly the live cache's builds, hits, evictions and bytes.
#include "core/cache/cache_simulator.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/cache/access_trace.h"
#include "core/cache/eviction_policy.h"
#include "core/query/query_engine.h"
#include "core/store/scene_packer.h"
#include "core/store/scene_store.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

AccessTrace trace_of(const std::vector<uint32_t>& bricks, uint64_t bytes = 100, uint64_t reserved = 0) {
  AccessTrace trace;
  std::vector<uint8_t> seen;
  for (const uint32_t b : bricks) {
    if (b >= seen.size()) seen.resize(b + 1, 0);
    AccessRecord r;
    r.seq = trace.records.size();
    r.brick = b;
    r.bytes = bytes;
    r.reserved_bytes = reserved;
    r.outcome = seen[b] ? AccessOutcome::kHit : AccessOutcome::kMiss;
    r.build_seconds = seen[b] ? 0.0 : 0.001 * (b + 1);
    seen[b] = 1;
    trace.records.push_back(r);
  }
  return trace;
}

TEST(CacheSimulatorTest, LruReplayByHand) {
  // Budget of three 100-byte bricks: 0 1 2 0 3 (evicts 1) 1 (evicts 2) 0.
  const AccessTrace trace = trace_of({0, 1, 2, 0, 3, 1, 0});
  const TraceProfile profile = TraceProfile::of(trace);
  EXPECT_EQ(profile.working_set_bytes, 400u);
  EXPECT_EQ(profile.distinct_bricks, 4u);
  auto result = simulate_policy(trace, profile, "lru", 300);
  ASSERT_TRUE(result.ok()) << result.status().to_string();
  EXPECT_EQ(result->requests, 7u);
  EXPECT_EQ(result->misses, 5u);
  EXPECT_EQ(result->hits, 2u);
  EXPECT_EQ(result->evictions, 2u);
  EXPECT_EQ(result->bytes_built, 500u);
  EXPECT_DOUBLE_EQ(result->build_seconds, 0.001 + 0.002 + 0.003 + 0.004 + 0.002);  // 1 rebuilt at its mean
  EXPECT_EQ(result->peak_resident_bytes, 300u);
  EXPECT_DOUBLE_EQ(result->miss_ratio(), 5.0 / 7.0);
}

TEST(CacheSimulatorTest, ReservationsAreMadeRoomForBeforeTheBuild) {
  // Bricks of 100 bytes reserving 200: a 300-byte budget holds two, not three.
  const AccessTrace trace = trace_of({0, 1, 2, 0}, 100, 200);
  const TraceProfile profile = TraceProfile::of(trace);
  auto result = simulate_policy(trace, profile, "lru", 300);
  ASSERT_TRUE(result.ok());
  EXPECT_EQ(result->misses, 4u);  // 2 evicts 0 (100 + 200 > 300 with both)
  EXPECT_EQ(result->peak_resident_bytes, 300u);
}

TEST(CacheSimulatorTest, ABrickLargerThanTheBudgetIsAnErrorNamingIt) {
  AccessTrace trace = trace_of({0, 1, 2});
  trace.records[2].reserved_bytes = 500;
  const TraceProfile profile = TraceProfile::of(trace);
  EXPECT_EQ(profile.largest_reservation, 500u);
  auto result = simulate_policy(trace, profile, "lru", 400);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kResourceExhausted);
  const std::string& message = result.status().message();
  EXPECT_NE(message.find("brick 2 (trace record 2) needs up to"), std::string::npos) << message;
  EXPECT_NE(message.find("smallest budget this trace can be replayed with is 0.00 MiB (500 bytes)"),
            std::string::npos)
      << message;
  EXPECT_FALSE(simulate_policy(trace, profile, "lru", 0).ok());
  auto unknown = simulate_policy(trace, profile, "mru", 1000);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
}

TEST(CacheSimulatorTest, EveryPolicyReplaysAConsistentCount) {
  std::mt19937 rng(7);
  std::vector<uint32_t> bricks;
  for (int i = 0; i < 3000; ++i) bricks.push_back(rng() % 3 == 0 ? rng() % 60 : rng() % 8);
  const AccessTrace trace = trace_of(bricks);
  const TraceProfile profile = TraceProfile::of(trace);
  for (const std::string& name : eviction_policy_names()) {
    for (const uint64_t budget : {100u, 500u, 2000u, 6000u}) {
      auto r = simulate_policy(trace, profile, name, budget);
      ASSERT_TRUE(r.ok()) << name << ": " << r.status().to_string();
      EXPECT_EQ(r->hits + r->misses, 3000u) << name;
      EXPECT_GE(r->misses, profile.distinct_bricks) << name;
      EXPECT_LE(r->peak_resident_bytes, budget) << name;
      EXPECT_EQ(r->bytes_built, 100 * r->misses) << name;
      if (budget >= profile.working_set_bytes) {
        EXPECT_EQ(r->misses, profile.distinct_bricks) << name;
      }
    }
  }
}

// ---- live cache vs replay ------------------------------------------------------

class LiveReplayTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    PackOptions options;
    options.inputs = {"gen:sphere?level=5"};
    options.output = dir_->file("scene");
    options.brick_triangles = 512;
    options.sync = false;
    const auto summary = pack_scene(options);
    ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string scene() { return dir_->file("scene"); }
  static testing::TempDir* dir_;
};
testing::TempDir* LiveReplayTest::dir_ = nullptr;

// Rays through random points of the unit sphere's box from outside it, in
// two batches (the second sees a warm cache).
std::vector<Ray> rays(std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Ray> out(n);
  for (Ray& ray : out) {
    ray.origin = {3.0f * u(rng), 3.0f * u(rng), 3.0f};
    const Vec3f target{u(rng), u(rng), u(rng)};
    ray.direction = target - ray.origin;
  }
  return out;
}

uint64_t largest_reservation(const SceneStore& store) {
  auto builder = make_brick_builder("embree", {});
  EXPECT_TRUE(builder.ok());
  uint64_t most = 0;
  for (const BrickRecord& brick : store.manifest().bricks)
    most = std::max(most, (*builder)->reserve_bytes(brick.triangle_count));
  return most;
}

TEST_F(LiveReplayTest, ReplayWithTheLivePolicyAndBudgetMatchesTheLiveCache) {
  // One thread: the engine builds several bricks at once when it has the
  // threads, and their reservations then overlap in the live cache, which a
  // sequential replay cannot see (its peak would be lower).
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  testing::TempDir dir;
  auto store = SceneStore::open(scene());
  ASSERT_TRUE(store.ok()) << store.status().to_string();
  for (const std::string& policy : eviction_policy_names()) {
    SCOPED_TRACE(policy);
    const std::string path = dir.file(policy + ".csv");
    auto writer = AccessTraceWriter::create(path, "live replay test");
    ASSERT_TRUE(writer.ok()) << writer.status().to_string();
    EngineOptions options;
    // Room for about four of the scene's 40 bricks.
    options.cache_bytes = 4 * largest_reservation(**store);
    options.eviction_policy = policy;
    options.access_trace = *writer;
    auto engine = QueryEngine::create(*store, options);
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    QueryOptions query;
    uint64_t acquisitions = 0, hits = 0;
    for (uint64_t batch = 0; batch < 3; ++batch) {
      // Small batches so bricks come back across batches (hits, evictions).
      const std::vector<Ray> batch_rays = rays(150, 100 + batch);
      std::vector<Hit> out(batch_rays.size());
      QueryStats stats;
      ASSERT_TRUE((*engine)->intersect(batch_rays, out, query, &stats).ok());
      acquisitions += stats.brick_acquisitions;
      hits += stats.cache_hits;
    }
    const CacheCounters live = (*engine)->cache().counters();
    engine->reset();
    ASSERT_TRUE((*writer)->close().ok());

    auto trace = read_access_trace(path);
    ASSERT_TRUE(trace.ok()) << trace.status().to_string();
    EXPECT_EQ(trace->info.policy, policy);
    EXPECT_EQ(trace->info.budget_bytes, options.cache_bytes);
    EXPECT_EQ(trace->info.bricks, (*store)->brick_count());
    ASSERT_EQ(trace->records.size(), acquisitions);
    ASSERT_GT(live.evictions, 0u) << "the budget was meant to be small";
    ASSERT_GT(hits, 0u);

    const TraceProfile profile = TraceProfile::of(*trace);
    auto replay = simulate_policy(*trace, profile, policy, trace->info.budget_bytes);
    ASSERT_TRUE(replay.ok()) << replay.status().to_string();
    EXPECT_EQ(replay->requests, live.hits + live.misses);
    EXPECT_EQ(replay->misses, live.builds);
    EXPECT_EQ(replay->hits, live.hits);
    EXPECT_EQ(replay->evictions, live.evictions);
    EXPECT_EQ(replay->bytes_built, live.bytes_built);
    EXPECT_DOUBLE_EQ(replay->build_seconds, live.build_seconds);
    EXPECT_EQ(replay->peak_resident_bytes, live.peak_resident_bytes);
    // Record by record: the replay misses exactly where the live cache built.
    uint64_t live_misses = 0;
    for (const AccessRecord& r : trace->records) live_misses += r.outcome == AccessOutcome::kMiss;
    EXPECT_EQ(live_misses, live.builds);
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
