// Engine-level tests of our brick structures ("bvh", "kdtree", "bsp", "grid", "hgrid", "octree", "quadtree")
// and the "reference" one: a packed store traced through QueryEngine with each structure and every triangle
// test answers as the float64 brute force does, bitwise the same with one big brick or many tiny ones, under
// a budget of two bricks, with the rays queued at bricks or run one by one, and across structures (both are
// exact walks over the same triangle test); the "reference" structure (what `outcore trace --reference` uses)
// agrees with brute_force_reference.h.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "core/accel/brute_force_reference.h"
#include "core/query/query_engine.h"
#include "core/store/scene_packer.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using Packed = testing::PackedScene;

std::unique_ptr<Packed> pack(const std::vector<std::string>& inputs, uint32_t brick_triangles) {
  return testing::pack_test_scene(inputs, brick_triangles);
}

std::vector<Ray> mixed_rays(const Aabb& box, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const Vec3f e = box.extent();
  auto point = [&](float grow) {
    return Vec3f(box.lo.x - grow * e.x + u(rng) * (1 + 2 * grow) * e.x,
                 box.lo.y - grow * e.y + u(rng) * (1 + 2 * grow) * e.y,
                 box.lo.z - grow * e.z + u(rng) * (1 + 2 * grow) * e.z);
  };
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    rays[i].origin = point(i % 3 == 0 ? 0.0f : 0.6f);
    rays[i].direction = point(0.0f) - rays[i].origin;
    if (rays[i].direction == Vec3f(0, 0, 0)) rays[i].direction = {0, 0, 1};
    if (i % 7 == 0) rays[i].tfar = 0.5f;
    if (i % 11 == 0) rays[i].tnear = 0.25f;
  }
  return rays;
}

std::vector<Hit> trace(const Packed& scene, const std::vector<Ray>& rays, const std::string& accel,
                       const BrickAccelOptions& options) {
  EngineOptions engine_options;
  engine_options.brick_accel = accel;
  engine_options.accel_options = options;
  auto engine = QueryEngine::open(scene.path, engine_options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  std::vector<Hit> hits(rays.size());
  const Status s = (*engine)->intersect(rays, hits, {});
  EXPECT_TRUE(s.ok()) << s.to_string();
  std::vector<uint8_t> occluded(rays.size());
  EXPECT_TRUE((*engine)->occluded(rays, occluded, {}).ok());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    EXPECT_EQ(occluded[i] != 0, hits[i].is_hit()) << accel << " ray " << i;
  }
  return hits;
}

// The float64 brute force's answer for each ray, computed once and held
// against every structure and test.
std::vector<ReferenceHit> reference_hits(const Packed& scene, const std::vector<Ray>& rays) {
  std::vector<ReferenceHit> refs;
  refs.reserve(rays.size());
  for (const Ray& ray : rays) refs.push_back(reference_closest_hit(scene.triangles, scene.ids, ray));
  return refs;
}

void expect_matches_reference(const std::vector<ReferenceHit>& refs, const std::vector<Hit>& hits,
                              const std::string& what) {
  ASSERT_EQ(refs.size(), hits.size()) << what;
  std::size_t disagreements = 0, hits_seen = 0;
  for (std::size_t i = 0; i < refs.size(); ++i) {
    const ReferenceHit& ref = refs[i];
    const Hit& h = hits[i];
    if (ref.is_hit() != h.is_hit()) {
      ++disagreements;
      continue;
    }
    if (!ref.is_hit()) continue;
    ++hits_seen;
    EXPECT_NEAR(h.t, ref.t, 1e-5 * std::max(1.0, ref.t)) << what << " ray " << i;
    if (h.geometry_id != ref.geometry_id || h.primitive_id != ref.primitive_id) {
      ++disagreements;
      continue;
    }
    EXPECT_NEAR(h.u, ref.u, 1e-3) << what << " ray " << i;
    EXPECT_NEAR(h.v, ref.v, 1e-3) << what << " ray " << i;
    EXPECT_EQ(h.normal, Vec3f(ref.normal)) << what << " ray " << i;
  }
  EXPECT_GT(hits_seen, refs.size() / 10) << what;
  EXPECT_LE(disagreements, refs.size() / 200) << what;
}

bool bitwise_equal(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
}

// Our structures with a triangle test option, each traced in every test.
constexpr const char* kStructures[] = {"bvh", "kdtree", "bsp", "grid", "hgrid", "octree", "quadtree"};

TEST(BrickStructureEngine, EveryTriangleTestMatchesTheReferenceAndBrickSizeDoesNotMatter) {
  const std::vector<std::string> inputs = {"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5",
                                           "gen:terrain?n=24&size=6&height=0.5"};
  const auto small = pack(inputs, 96);
  const auto big = pack(inputs, 1u << 20);
  const auto rays = mixed_rays(small->bounds, 2500, 1);
  const std::vector<ReferenceHit> refs = reference_hits(*small, rays);
  for (const char* test : {"mt", "watertight", "double"}) {
    std::vector<Hit> first;
    for (const char* structure : kStructures) {
      const std::string what = std::string(structure) + " " + test;
      const auto hits = trace(*small, rays, structure, {{"triangle_test", test}});
      expect_matches_reference(refs, hits, what);
      if (std::string(test) != "mt") {
        // Watertight tests: brick seams are no weaker than a brick's inside.
        EXPECT_TRUE(bitwise_equal(hits, trace(*big, rays, structure, {{"triangle_test", test}}))) << what;
      }
      if (first.empty()) first = hits;
      EXPECT_TRUE(bitwise_equal(hits, first)) << what << ": the same answers as " << kStructures[0];
    }
  }
}

TEST(BrickStructureEngine, BunnyMatchesTheReference) {
  const auto scene = pack({testing::model_path("stanford-bunny.obj")}, 4096);
  const auto rays = mixed_rays(scene->bounds, 1000, 2);
  const std::vector<ReferenceHit> refs = reference_hits(*scene, rays);
  for (const char* structure : kStructures) {
    expect_matches_reference(refs, trace(*scene, rays, structure, {}), structure);
  }
}

// Rays run one by one in input order (no queues at bricks) answer bitwise as
// the queued batch.
TEST(BrickStructureEngine, ReorderOnAndOffAnswerTheSame) {
  const auto scene = pack({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5"}, 200);
  const auto rays = mixed_rays(scene->bounds, 2000, 5);
  for (const char* structure : kStructures) {
    EngineOptions options;
    options.brick_accel = structure;
    auto engine = QueryEngine::open(scene->path, options);
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    std::vector<Hit> queued(rays.size()), sequential(rays.size());
    ASSERT_TRUE((*engine)->intersect(rays, queued, {}).ok());
    QueryOptions one_by_one;
    one_by_one.reorder = false;
    ASSERT_TRUE((*engine)->intersect(rays, sequential, one_by_one).ok());
    EXPECT_TRUE(bitwise_equal(queued, sequential)) << structure;
  }
}

TEST(BrickStructureEngine, ReferenceStructureAgreesWithTheBruteForce) {
  const auto scene = pack({"gen:sphere?level=3", "gen:torus?nu=32&nv=16&cx=1.5"}, 128);
  const auto rays = mixed_rays(scene->bounds, 1500, 3);
  const auto hits = trace(*scene, rays, "reference", {});
  expect_matches_reference(reference_hits(*scene, rays), hits, "reference");
  // And bvh with the double test is the same computation behind boxes.
  EXPECT_TRUE(bitwise_equal(hits, trace(*scene, rays, "bvh", {{"triangle_test", "double"}})));
}

void expect_tiny_budget_answers_like_unlimited(const Packed& scene, const std::vector<Ray>& rays,
                                               const std::string& structure) {
  const auto unlimited = trace(scene, rays, structure, {});
  EngineOptions options;
  options.brick_accel = structure;
  auto probe = QueryEngine::open(scene.path, options);
  ASSERT_TRUE(probe.ok());
  uint64_t most = 0;
  for (const auto& b : (*probe)->store().manifest().bricks) {
    most = std::max(most, (*probe)->cache().builder().reserve_bytes(b.triangle_count));
  }
  options.cache_bytes = 2 * most;
  auto engine = QueryEngine::open(scene.path, options);
  ASSERT_TRUE(engine.ok());
  std::vector<Hit> hits(rays.size());
  QueryStats stats;
  ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
  EXPECT_TRUE(bitwise_equal(hits, unlimited));
  EXPECT_GT(stats.evictions, 0u);
  EXPECT_LE(stats.peak_bytes_resident, options.cache_bytes);
  EXPECT_EQ((*engine)->cache().counters().reservation_overruns, 0u);
}

// The cache admits bricks on their reserve_bytes(): with a budget of two
// bricks every build fits its reservation and the answers are bitwise those
// of an unlimited budget.
TEST(BrickStructureEngine, TinyBudgetAnswersLikeAnUnlimitedOneWithinItsReservations) {
  const auto scene = pack({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5"}, 128);
  const auto rays = mixed_rays(scene->bounds, 2000, 4);
  for (const char* structure : kStructures) {
    SCOPED_TRACE(structure);
    expect_tiny_budget_answers_like_unlimited(*scene, rays, structure);
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
