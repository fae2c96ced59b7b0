// Engine-level tests of `--brick-accel auto`: traced through QueryEngine on
// a packed store of many bricks, auto answers bitwise as the bvh does (every
// candidate is an exact walk over the same watertight test) under an
// unlimited budget and one of two bricks, queued, one ray at a time and in
// the in-cache sweep, for closest and any hit, with a subtree tier, and while
// batches of growing use make it rebuild bricks as better structures; the
// statistics count builds per structure and the access trace records them.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/cache/access_trace.h"
#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using Packed = testing::PackedScene;

struct Answers {
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
  std::vector<QueryStats> stats;  // one per batch
};

// `batches` runs of `rays` through one engine (the cache warm after the
// first), each batch's answers compared with the first's.
Answers trace(const Packed& scene, const std::vector<Ray>& rays, EngineOptions options,
              const QueryOptions& query = {}, int batches = 1) {
  Answers out;
  auto engine = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  if (!engine.ok()) return out;
  for (int b = 0; b < batches; ++b) {
    std::vector<Hit> hits(rays.size());
    QueryStats stats;
    const Status s = (*engine)->intersect(rays, hits, query, &stats);
    EXPECT_TRUE(s.ok()) << s.to_string();
    if (b == 0) {
      out.hits = hits;
    } else {
      EXPECT_EQ(std::memcmp(hits.data(), out.hits.data(), hits.size() * sizeof(Hit)), 0) << "batch " << b;
    }
    out.stats.push_back(stats);
  }
  out.occluded.resize(rays.size());
  EXPECT_TRUE((*engine)->occluded(rays, out.occluded, query).ok());
  return out;
}

EngineOptions with_accel(const std::string& accel, uint64_t cache_bytes = uint64_t{1} << 30) {
  EngineOptions options;
  options.brick_accel = accel;
  options.cache_bytes = cache_bytes;
  return options;
}

void expect_same(const Answers& a, const Answers& b, const std::string& what) {
  ASSERT_EQ(a.hits.size(), b.hits.size()) << what;
  EXPECT_EQ(std::memcmp(a.hits.data(), b.hits.data(), a.hits.size() * sizeof(Hit)), 0) << what;
  EXPECT_EQ(a.occluded, b.occluded) << what;
}

uint64_t builds_by_structure_sum(const QueryStats& s) {
  return s.builds_embree + s.builds_bvh + s.builds_kdtree + s.builds_bsp + s.builds_grid + s.builds_hgrid +
         s.builds_octree + s.builds_quadtree + s.builds_reference;
}

class AutoEngine : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = testing::pack_test_scene({testing::model_path("stanford-bunny.obj"), "gen:stadium?level=3",
                                       "gen:terrain?n=40&size=4&height=0.3"},
                                      2048)
                 .release();
    bunny_ = testing::pack_test_scene({testing::model_path("stanford-bunny.obj")}, 4096).release();
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete bunny_;
  }
  static Packed* scene_;  // mixed scales: a stadium, a terrain and the bunny
  static Packed* bunny_;  // 20 bricks of ~3.5 k triangles
};
Packed* AutoEngine::scene_ = nullptr;
Packed* AutoEngine::bunny_ = nullptr;

TEST_F(AutoEngine, AnswersAreBitwiseTheBvhsAcrossBudgetsAndStrategies) {
  for (const auto& [scene, brick_triangles] : {std::pair{scene_, 2048}, std::pair{bunny_, 4096}}) {
    // On the mixed scene, aimed at its small parts (the terrain and the
    // bunny at the stadium's centre), so that many bricks are visited.
    const Aabb centre{Vec3f(-3, -3, -3), Vec3f(3, 3, 3)};
    const std::vector<Ray> rays = testing::make_test_rays(scene == bunny_ ? scene->bounds : centre, 6000, 3);
    const Answers bvh = trace(*scene, rays, with_accel("bvh"));
    ASSERT_FALSE(bvh.hits.empty());
    // About two bricks' worth of budget: bricks are evicted and rebuilt.
    const uint64_t tight = uint64_t{500} * brick_triangles;
    QueryOptions sequential;
    sequential.reorder = false;
    QueryOptions no_sweep;
    no_sweep.in_cache_sweep = false;
    struct Case {
      const char* what;
      EngineOptions options;
      QueryOptions query;
      bool evicts;
    } cases[] = {
        {"unlimited, queued then swept", with_accel("auto"), {}, false},
        {"unlimited, queued only", with_accel("auto"), no_sweep, false},
        {"unlimited, one ray at a time", with_accel("auto"), sequential, false},
        {"a two-brick budget", with_accel("auto", tight), {}, true},
        {"a two-brick budget, one ray at a time", with_accel("auto", tight), sequential, true},
    };
    for (const Case& c : cases) {
      const std::string what = std::string(c.what) + (scene == bunny_ ? ", bunny" : ", mixed");
      const Answers got = trace(*scene, rays, c.options, c.query, 3);
      expect_same(got, bvh, what);
      uint64_t builds = 0, evictions = 0;
      for (const QueryStats& s : got.stats) {
        EXPECT_EQ(builds_by_structure_sum(s), s.brick_builds) << what;
        EXPECT_EQ(s.builds_embree + s.builds_reference, 0u) << what;
        builds += s.brick_builds;
        evictions += s.evictions;
      }
      EXPECT_GT(builds, 0u) << what;
      EXPECT_EQ(evictions > 0, c.evicts) << what;
    }
  }
}

TEST_F(AutoEngine, BricksUsedAgainAndAgainAreRebuiltAsBetterStructuresWithTheSameAnswers) {
  // Few rays a brick: the first batch builds the cheapest structures (the
  // built-in profile's grid); as the same bricks keep serving batches,
  // their rays pay for a better one (its bvh).
  const std::vector<Ray> rays = testing::make_test_rays(bunny_->bounds, 2000, 8);
  const Answers bvh = trace(*bunny_, rays, with_accel("bvh"));
  for (const bool sweep : {true, false}) {
    QueryOptions query;
    query.in_cache_sweep = sweep;
    const Answers got = trace(*bunny_, rays, with_accel("auto"), query, 40);
    expect_same(got, bvh, sweep ? "swept" : "queued");
    uint64_t rebuilds = 0, bvh_builds = 0;
    for (const QueryStats& s : got.stats) rebuilds += s.brick_rebuilds, bvh_builds += s.builds_bvh;
    EXPECT_EQ(got.stats[0].brick_rebuilds, 0u) << got.stats[0].to_json();
    EXPECT_GT(got.stats[0].builds_grid, 0u)
        << "few rays: the cheapest build first " << got.stats[0].to_json();
    EXPECT_GT(rebuilds, 0u) << (sweep ? "swept" : "queued");
    EXPECT_GT(bvh_builds, 0u) << "many rays over time: the cheapest trace";
  }
}

TEST_F(AutoEngine, LargeWarmBatchesUseTheResidentSetOnlyWhenEveryBrickChoseTheBvh) {
  // Few enough bricks for a resident set. The first batch is small (each
  // brick built cheap, as grids); the large batches after it find a mix, so
  // the engine sweeps them through the bricks instead (each brick acquired
  // once a batch), until their rays have made auto rebuild every brick as a
  // bvh; then they go through the bvh's resident set.
  const std::unique_ptr<Packed> small =
      testing::pack_test_scene({testing::model_path("stanford-bunny.obj")}, 16384);
  QueryOptions large;
  large.brick_set_min_rays = 1000;
  const std::vector<Ray> few = testing::make_test_rays(small->bounds, 300, 21);
  const std::vector<Ray> rays = testing::make_test_rays(small->bounds, 4000, 22);
  std::vector<Hit> want(rays.size());
  {
    auto bvh = QueryEngine::open(small->path, with_accel("bvh"));
    ASSERT_TRUE(bvh.ok());
    ASSERT_TRUE((*bvh)->intersect(rays, want, large).ok());
  }
  auto engine = QueryEngine::open(small->path, with_accel("auto"));
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const uint32_t bricks = (*engine)->store().brick_count();
  ASSERT_LE(bricks, 16u);
  std::vector<Hit> hits(rays.size());
  QueryStats first;
  ASSERT_TRUE((*engine)->intersect(std::span(few), std::span(hits.data(), few.size()), large, &first).ok());
  EXPECT_GT(first.builds_grid, 0u) << first.to_json();
  bool swept = false, set = false;
  for (int batch = 0; batch < 60 && !set; ++batch) {
    QueryStats stats;
    ASSERT_TRUE((*engine)->intersect(rays, hits, large, &stats).ok());
    EXPECT_EQ(std::memcmp(hits.data(), want.data(), hits.size() * sizeof(Hit)), 0) << "batch " << batch;
    // Every brick resident: one acquisition a brick, never two.
    EXPECT_EQ(stats.brick_acquisitions, bricks) << stats.to_json();
    if (stats.rays_in_brick_set == 0) {
      swept = true;
      EXPECT_GT(stats.brick_visits, 0u);
    } else {
      set = true;
      EXPECT_EQ(stats.rays_in_brick_set, rays.size());
    }
  }
  EXPECT_TRUE(swept) << "a mix of structures is swept";
  EXPECT_TRUE(set) << "once every brick is a bvh, its resident set serves";
}

TEST_F(AutoEngine, ASubtreeTierKeepsTheChosenStructuresAndTheAnswers) {
  testing::TempDir tier;
  const std::vector<Ray> rays = testing::make_test_rays(bunny_->bounds, 4000, 4);
  const Answers bvh = trace(*bunny_, rays, with_accel("bvh"));
  EngineOptions options = with_accel("auto", uint64_t{500} * 4096);
  options.subtree_dir = tier.path();
  const Answers first = trace(*bunny_, rays, options, {}, 2);
  expect_same(first, bvh, "tier, first engine");
  const Answers second = trace(*bunny_, rays, options, {}, 2);
  expect_same(second, bvh, "tier, second engine");
  uint64_t loads = 0;
  for (const QueryStats& s : second.stats) loads += s.subtree_loads;
  EXPECT_GT(loads, 0u);
}

TEST_F(AutoEngine, TheAccessTraceRecordsEachBricksStructureAndRays) {
  testing::TempDir dir;
  const std::string path = dir.file("trace.csv");
  const std::vector<Ray> rays = testing::make_test_rays(scene_->bounds, 2000, 5);
  {
    EngineOptions options = with_accel("auto");
    auto writer = AccessTraceWriter::create(path, "test");
    ASSERT_TRUE(writer.ok());
    options.access_trace = *writer;
    trace(*scene_, rays, options, {}, 1);
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto read = read_access_trace(path);
  ASSERT_TRUE(read.ok()) << read.status().to_string();
  ASSERT_FALSE(read->records.empty());
  uint64_t misses = 0, rays_seen = 0;
  for (const AccessRecord& r : read->records) {
    EXPECT_NE(brick_structure_index(r.structure), kMaxBrickStructures) << r.structure;
    EXPECT_NE(r.structure, "auto");
    if (r.outcome == AccessOutcome::kMiss) ++misses;
    rays_seen += r.rays;
  }
  EXPECT_GT(misses, 0u);
  EXPECT_GT(rays_seen, 0u);
  EXPECT_EQ(read->info.builder, "auto");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
