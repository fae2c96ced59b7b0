// --brick-bounds through the engine (core/upper/brick_bounds.h): on a tilted
// city packed into small bricks, every bound gives bitwise the answers of the
// upper hierarchy's boxes alone (closest and any hit, every brick structure
// with its rounding), and the statistics add up exactly: with proxies off,
// each candidate a bound turns away is a visit the box let in that found
// nothing (visits(aabb) = visits(bound) + skipped_by_bound and the same for
// visits without a hit); the oriented box turns away more than the sphere on
// this scene of oblique flat patches. brick_visits_without_hit itself is checked on rays
// that enter a brick and can hit nothing.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

struct Traced {
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
  QueryStats stats, any_stats;
};

Traced trace(const testing::PackedScene& scene, const std::vector<Ray>& rays, const std::string& accel,
             const std::string& bounds, bool proxies) {
  EngineOptions options;
  options.brick_accel = accel;
  options.brick_bounds = bounds;
  options.proxies = proxies;
  auto engine = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  Traced out;
  out.hits.resize(rays.size());
  out.occluded.resize(rays.size());
  QueryOptions query;
  query.brick_set = false;  // the walk over bricks, whose visits are counted
  EXPECT_TRUE((*engine)->intersect(rays, out.hits, query, &out.stats).ok());
  EXPECT_TRUE((*engine)->occluded(rays, out.occluded, query, &out.any_stats).ok());
  return out;
}

TEST(BrickBoundsEngine, EveryBoundAnswersBitwiseAsTheBoxesAndTheCountsAddUp) {
  const auto scene = testing::pack_test_scene(
      {"gen:city?of=(gen:terrain?n=10&size=2&height=0.05)&copies=100&spacing=3&tilt=30"}, 200);
  const auto rays = testing::make_test_rays(scene->bounds, 4000, 5);
  for (const char* accel : {"bvh", "embree", "kdtree", "bsp", "grid", "hgrid", "octree", "quadtree"}) {
    SCOPED_TRACE(accel);
    for (const bool proxies : {false, true}) {
      const Traced boxes = trace(*scene, rays, accel, "aabb", proxies);
      EXPECT_EQ(boxes.stats.bricks_skipped_by_bound, 0u);
      EXPECT_GT(boxes.stats.brick_visits_without_hit, 0u);
      EXPECT_LE(boxes.stats.brick_visits_without_hit, boxes.stats.brick_visits);
      uint64_t turned_away[2] = {0, 0};
      int k = 0;
      for (const char* bounds : {"sphere", "obb"}) {
        SCOPED_TRACE(bounds);
        const Traced t = trace(*scene, rays, accel, bounds, proxies);
        EXPECT_EQ(std::memcmp(t.hits.data(), boxes.hits.data(), rays.size() * sizeof(Hit)), 0);
        EXPECT_EQ(t.occluded, boxes.occluded);
        EXPECT_GT(t.stats.bricks_skipped_by_bound, 0u);
        if (!proxies) {
          EXPECT_EQ(t.stats.brick_visits + t.stats.bricks_skipped_by_bound, boxes.stats.brick_visits);
          EXPECT_EQ(t.stats.brick_visits_without_hit + t.stats.bricks_skipped_by_bound,
                    boxes.stats.brick_visits_without_hit);
          EXPECT_EQ(t.any_stats.brick_visits + t.any_stats.bricks_skipped_by_bound,
                    boxes.any_stats.brick_visits);
        }
        turned_away[k++] = t.stats.bricks_skipped_by_bound;
      }
      EXPECT_GT(turned_away[1], turned_away[0]) << "the oriented box fits the tilted flat patches better";
    }
  }
}

TEST(BrickBoundsEngine, VisitsWithoutAHitCountRaysThatFindNothing) {
  // One brick, a sphere: rays through its box's corners miss the sphere.
  const auto scene = testing::pack_test_scene({"gen:sphere?level=3"}, 1u << 20);
  const Aabb b = scene->bounds;
  std::vector<Ray> misses, hits;
  for (int i = 0; i < 50; ++i) {
    const float f = 0.001f * static_cast<float>(i);
    misses.push_back({Vec3f(b.lo.x - 1, b.lo.y + f, b.lo.z + f), Vec3f(1, 0, 0)});
    hits.push_back(
        {Vec3f(b.lo.x - 1, 0.5f * (b.lo.y + b.hi.y) + f, 0.5f * (b.lo.z + b.hi.z)), Vec3f(1, 0, 0)});
  }
  const Traced missed = trace(*scene, misses, "bvh", "aabb", false);
  EXPECT_EQ(missed.stats.brick_visits, misses.size());
  EXPECT_EQ(missed.stats.brick_visits_without_hit, misses.size());
  EXPECT_EQ(missed.any_stats.brick_visits_without_hit, misses.size());
  const Traced hit = trace(*scene, hits, "bvh", "aabb", false);
  EXPECT_EQ(hit.stats.brick_visits, hits.size());
  EXPECT_EQ(hit.stats.brick_visits_without_hit, 0u);
  EXPECT_EQ(hit.any_stats.brick_visits_without_hit, 0u);
  // The sphere bound turns the corner rays away before the brick.
  const Traced bounded = trace(*scene, misses, "bvh", "sphere", false);
  EXPECT_EQ(bounded.stats.brick_visits, 0u);
  EXPECT_EQ(bounded.stats.bricks_skipped_by_bound, misses.size());
}

TEST(BrickBoundsEngine, AnUnknownBoundIsAnErrorNamingIt) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=1"}, 1u << 20);
  EngineOptions options;
  options.brick_bounds = "kdop";
  auto engine = QueryEngine::open(scene->path, options);
  ASSERT_FALSE(engine.ok());
  EXPECT_EQ(engine.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(engine.status().message().find("'kdop'"), std::string::npos) << engine.status().message();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
