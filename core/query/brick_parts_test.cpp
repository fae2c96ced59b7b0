// Batches that trace a part of the scene (QueryOptions::only_bricks, what a
// replica that owns some bricks answers; docs/SCALING.md): the parts' hits
// merged by the tie rule are bitwise the whole scene's, occlusion is the OR
// of the parts', under any budget (trace-ahead included), whether the other
// bricks are resident or not (the resident set is never taken for a part),
// for camera packets and incoherent rays; a part builds only its own bricks;
// bad ids and every-hit queries with a part are INVALID_ARGUMENT.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::open_test_engine;

// A pinhole camera outside the box looking at its centre: coherent rays,
// traced as packets.
std::vector<Ray> camera_rays(const Aabb& box, int side) {
  const Vec3f centre = (box.lo + box.hi) * 0.5f;
  const Vec3f e = box.extent();
  const Vec3f eye = centre + Vec3f(0.4f * e.x, 0.3f * e.y, 2.5f * std::max({e.x, e.y, e.z}));
  std::vector<Ray> rays;
  for (int y = 0; y < side; ++y) {
    for (int x = 0; x < side; ++x) {
      const Vec3f target = box.lo + Vec3f(e.x * (x + 0.5f) / side, e.y * (y + 0.5f) / side, e.z * 0.5f);
      Ray r;
      r.origin = eye;
      r.direction = target - eye;
      rays.push_back(r);
    }
  }
  return rays;
}

struct Answers {
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
  QueryStats stats;
};

Answers trace(QueryEngine& engine, const std::vector<Ray>& rays, const QueryOptions& options) {
  Answers a;
  a.hits.resize(rays.size());
  a.occluded.resize(rays.size());
  const Status closest = engine.intersect(rays, a.hits, options, &a.stats);
  EXPECT_TRUE(closest.ok()) << closest.to_string();
  const Status any = engine.occluded(rays, a.occluded, options);
  EXPECT_TRUE(any.ok()) << any.to_string();
  return a;
}

// The parts' answers combined as a replicated client does.
void merge_into(Answers& merged, const Answers& part) {
  for (std::size_t i = 0; i < part.hits.size(); ++i) {
    const Hit& h = part.hits[i];
    if (h.is_hit() && hit_is_better(h.t, h.geometry_id, h.primitive_id, merged.hits[i])) merged.hits[i] = h;
    merged.occluded[i] = merged.occluded[i] | part.occluded[i];
  }
}

bool bitwise_equal(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
}

// Brick ids split into `parts` parts: interleaved (every part all over the
// scene) or in runs of consecutive ids.
std::vector<std::vector<uint32_t>> split_bricks(uint32_t bricks, uint32_t parts, bool interleaved) {
  std::vector<std::vector<uint32_t>> out(parts);
  for (uint32_t b = 0; b < bricks; ++b) out[interleaved ? b % parts : b * parts / bricks].push_back(b);
  return out;
}

TEST(BrickParts, PartsMergedByTheTieRuleAnswerBitwiseAsTheWholeScene) {
  struct Case {
    std::vector<std::string> inputs;
    uint32_t brick_triangles;
  };
  // Duplicated spheres: every hit a tie across bricks; a stadium: bricks of
  // very different sizes, overlapping boxes.
  const std::vector<Case> cases = {
      {{"gen:sphere?level=4", "gen:sphere?level=4"}, 700},
      {{"gen:stadium?size=50&level=4&object=2&segments=4"}, 900},
  };
  for (const Case& c : cases)
    for (const char* structure : {"bvh", "embree"}) {
      SCOPED_TRACE(std::string(structure) + " " + c.inputs[0]);
      const auto scene = testing::pack_test_scene(c.inputs, c.brick_triangles);
      std::vector<Ray> rays = testing::make_test_rays(scene->bounds, 4000, 11);
      const std::vector<Ray> camera = camera_rays(scene->bounds, 48);
      rays.insert(rays.end(), camera.begin(), camera.end());
      auto whole_engine = open_test_engine(*scene, structure);
      const uint32_t bricks = whole_engine->store().brick_count();
      ASSERT_GE(bricks, 4u);
      const Answers whole = trace(*whole_engine, rays, {});
      std::size_t hits = 0;
      for (const Hit& h : whole.hits) hits += h.is_hit();
      ASSERT_GT(hits, rays.size() / 5);

      // The budget of the largest brick: bricks evicted and built again,
      // trace-ahead at work.
      uint64_t one_brick = 0;
      for (const BrickRecord& b : whole_engine->store().manifest().bricks)
        one_brick = std::max(one_brick, whole_engine->cache().builder().reserve_bytes(b.triangle_count));
      for (const uint64_t budget : {uint64_t{1} << 30, one_brick})
        for (const bool interleaved : {true, false}) {
          SCOPED_TRACE("budget " + std::to_string(budget) + (interleaved ? " interleaved" : " runs"));
          Answers merged{std::vector<Hit>(rays.size()), std::vector<uint8_t>(rays.size(), 0), {}};
          for (const std::vector<uint32_t>& part : split_bricks(bricks, 3, interleaved)) {
            auto engine = open_test_engine(*scene, structure, budget);
            QueryOptions options;
            options.only_bricks = part;
            const Answers got = trace(*engine, rays, options);
            EXPECT_LE(got.stats.brick_builds, part.size() * (budget == one_brick ? 64 : 1));
            for (const uint32_t b : engine->cache().resident_bricks())
              EXPECT_TRUE(std::find(part.begin(), part.end(), b) != part.end()) << "brick " << b << " built";
            merge_into(merged, got);
          }
          EXPECT_TRUE(bitwise_equal(merged.hits, whole.hits));
          EXPECT_EQ(merged.occluded, whole.occluded);
        }

      // Under a budget of a few bricks, after a whole-scene batch left bricks
      // outside the part resident: trace-ahead must not use them.
      auto warm = open_test_engine(*scene, structure, 3 * one_brick);
      Answers merged_warm{std::vector<Hit>(rays.size()), std::vector<uint8_t>(rays.size(), 0), {}};
      for (const std::vector<uint32_t>& part : split_bricks(bricks, 2, false)) {
        EXPECT_TRUE(bitwise_equal(trace(*warm, rays, {}).hits, whole.hits));
        QueryOptions options;
        options.only_bricks = part;
        const Answers got = trace(*warm, rays, options);
        // Exactly the part's answers: no hit from a brick outside it.
        const Answers alone = trace(*open_test_engine(*scene, structure), rays, options);
        EXPECT_TRUE(bitwise_equal(got.hits, alone.hits));
        EXPECT_EQ(got.occluded, alone.occluded);
        merge_into(merged_warm, got);
      }
      EXPECT_TRUE(bitwise_equal(merged_warm.hits, whole.hits));
      EXPECT_EQ(merged_warm.occluded, whole.occluded);

      // Every brick resident (the whole batch ran first), a large batch:
      // the resident set would be taken for the whole scene, never for a part.
      Answers merged{std::vector<Hit>(rays.size()), std::vector<uint8_t>(rays.size(), 0), {}};
      for (const std::vector<uint32_t>& part : split_bricks(bricks, 2, true)) {
        QueryOptions options;
        options.brick_set_min_rays = 0;
        options.only_bricks = part;
        const std::vector<uint32_t> before = whole_engine->cache().resident_bricks();
        const Answers got = trace(*whole_engine, rays, options);
        EXPECT_EQ(got.stats.rays_in_brick_set, 0u);
        // A brick no ray of the whole scene reached (each found a nearer hit
        // first) may be built for the part, never one outside it.
        for (const uint32_t b : whole_engine->cache().resident_bricks()) {
          if (std::find(before.begin(), before.end(), b) != before.end()) continue;
          EXPECT_TRUE(std::find(part.begin(), part.end(), b) != part.end()) << "brick " << b << " built";
        }
        merge_into(merged, got);
      }
      EXPECT_TRUE(bitwise_equal(merged.hits, whole.hits));
      EXPECT_EQ(merged.occluded, whole.occluded);
    }
}

TEST(BrickParts, APartOfEveryBrickAnswersAsNoPartAndAnEmptyPartIsEveryBrick) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=4"}, 400);
  auto engine = open_test_engine(*scene, "bvh");
  const std::vector<Ray> rays = testing::make_test_rays(scene->bounds, 2000, 3);
  const Answers whole = trace(*engine, rays, {});
  QueryOptions every;
  for (uint32_t b = engine->store().brick_count(); b-- > 0;) every.only_bricks.push_back(b);
  every.only_bricks.push_back(0);  // a repeat is allowed
  const Answers got = trace(*engine, rays, every);
  EXPECT_TRUE(bitwise_equal(got.hits, whole.hits));
  EXPECT_EQ(got.occluded, whole.occluded);
  // Restricted to every brick, the walks are the whole hierarchy's.
  EXPECT_EQ(got.stats.upper_nodes_visited, whole.stats.upper_nodes_visited);
}

TEST(BrickParts, ABrickIdOutOfRangeOrAPartOnEveryHitQueriesIsInvalidArgument) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=3"}, 300);
  auto engine = open_test_engine(*scene, "bvh");
  const uint32_t bricks = engine->store().brick_count();
  const std::vector<Ray> rays = testing::make_test_rays(scene->bounds, 100, 5);
  QueryOptions bad;
  bad.only_bricks = {0, bricks};
  std::vector<Hit> hits(rays.size());
  const Status s = engine->intersect(rays, hits, bad);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("brick " + std::to_string(bricks) + " is not in the scene"), std::string::npos)
      << s.message();
  std::vector<uint8_t> occluded(rays.size());
  EXPECT_EQ(engine->occluded(rays, occluded, bad).code(), StatusCode::kInvalidArgument);
  QueryOptions part;
  part.only_bricks = {0};
  std::vector<uint32_t> counts(rays.size());
  const Status every_hit = engine->all_hits(rays, counts, nullptr, part);
  EXPECT_EQ(every_hit.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(every_hit.message().find("only_bricks"), std::string::npos) << every_hit.message();
  // The engine is unharmed.
  EXPECT_TRUE(engine->intersect(rays, hits, part).ok());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
