#include "core/accel/bvh/bvh_brick.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brute_force_reference.h"
#include "core/accel/bvh/bvh_traversal.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::bounds_of;
using accel_test::load_brick_from;

constexpr auto& kAllTests = kAllTriangleTests;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 600;
#else
constexpr std::size_t kRays = 4000;
#endif

std::unique_ptr<BvhBrickAccel> build(BrickData brick, TriangleTest test,
                                     BinnedSahBuilder::Config builder = {}) {
  BvhBrickConfig config;
  config.triangle_test = test;
  config.builder = builder;
  auto accel = BvhBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return std::move(accel).value();
}

std::vector<Ray> test_rays(const BrickData& brick, std::size_t n, uint64_t seed) {
  const Aabb b = bounds_of(brick);
  auto rays = accel_test::rays_from_outside(b, n / 2, seed);
  const auto inside = accel_test::rays_from_inside(b, n - n / 2, seed + 1);
  rays.insert(rays.end(), inside.begin(), inside.end());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (i % 7 == 3) rays[i].tfar = 0.3f * length(b.extent());
    if (i % 11 == 5) rays[i].tnear = 0.05f * length(b.extent());
  }
  return rays;
}

// Compares closest hits with the float64 brute force; disagreements are
// allowed only where a ray grazes an edge (at most 1 in 200) or at a true tie.
void expect_closest_hits_match(const std::vector<ReferenceHit>& refs, const std::vector<Hit>& hits,
                               std::size_t min_hits, const std::string& what) {
  std::size_t disagreements = 0, hits_seen = 0;
  for (std::size_t i = 0; i < refs.size(); ++i) {
    const ReferenceHit& ref = refs[i];
    const Hit& h = hits[i];
    if (ref.is_hit() != h.is_hit()) {
      ++disagreements;
      continue;
    }
    if (!ref.is_hit()) {
      EXPECT_EQ(h.t, std::numeric_limits<float>::infinity()) << what << " ray " << i;
      continue;
    }
    ++hits_seen;
    EXPECT_NEAR(h.t, ref.t, 1e-5 * std::max(1.0, ref.t)) << what << " ray " << i;
    if (h.geometry_id != ref.geometry_id || h.primitive_id != ref.primitive_id) {
      ++disagreements;  // a tie within float precision
      continue;
    }
    EXPECT_NEAR(h.u, ref.u, 1e-3) << what << " ray " << i;
    EXPECT_NEAR(h.v, ref.v, 1e-3) << what << " ray " << i;
    EXPECT_EQ(h.normal, Vec3f(ref.normal)) << what << " ray " << i;  // same float64 formula, rounded
  }
  EXPECT_GE(hits_seen, min_hits) << what;
  EXPECT_LE(disagreements, refs.size() / 200) << what;
}

// Every triangle test, closest and any hit, against the brute force
// (computed once). min_hit_fraction: the rays that must find something.
void check_against_reference(const std::string& what, const BrickData& brick, uint64_t seed,
                             std::size_t n = kRays, double min_hit_fraction = 0.1) {
  const auto rays = test_rays(brick, n, seed);
  std::vector<ReferenceHit> refs;
  std::vector<uint8_t> ref_any;
  for (const Ray& ray : rays) {
    refs.push_back(reference_closest_hit(brick.triangles, brick.ids, ray));
    ref_any.push_back(reference_any_hit(brick.triangles, ray) ? 1 : 0);
  }
  const auto min_hits = static_cast<std::size_t>(min_hit_fraction * static_cast<double>(rays.size()));
  for (const TriangleTest test : kAllTests) {
    const auto accel = build(brick, test);
    const std::string name = what + " " + std::string(triangle_test_name(test));
    std::vector<Hit> hits(rays.size());
    accel->intersect(all_ids(rays.size()), rays.data(), hits.data());
    expect_closest_hits_match(refs, hits, min_hits, name);
    std::vector<uint8_t> occluded(rays.size(), 0);
    accel->occluded(all_ids(rays.size()), rays.data(), occluded.data());
    std::size_t any_disagreements = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (occluded[i] != ref_any[i]) ++any_disagreements;
      // The any-hit answer is the closest-hit answer's hit/miss.
      EXPECT_EQ(occluded[i] != 0, hits[i].is_hit()) << name << " ray " << i;
    }
    EXPECT_LE(any_disagreements, rays.size() / 200) << name;
  }
}

TEST(BvhBrick, MatchesTheFloat64ReferenceOnGeneratedScenes) {
  check_against_reference("sphere", load_brick_from("gen:sphere?level=4"), 1);
  check_against_reference("torus", load_brick_from("gen:torus?nu=48&nv=24"), 2);
  check_against_reference("terrain", load_brick_from("gen:terrain?n=24&size=6&height=0.5"), 3);
}

TEST(BvhBrick, MatchesTheFloat64ReferenceOnSyntheticSoups) {
  check_against_reference("random", accel_test::random_triangles(1500, 4), 4);
  // Small triangles scattered in a cube: few rays hit anything.
  check_against_reference("scattered", accel_test::scattered_triangles(3000, 5), 5, kRays, 0.01);
  check_against_reference("degenerate-heavy", accel_test::degenerate_heavy(3000, 6), 6, kRays, 0.01);
}

TEST(BvhBrick, MatchesTheFloat64ReferenceOnTheBunny) {
  check_against_reference("bunny", load_brick_from(accel_test::bunny_path()), 7, kRays / 4);
}

TEST(BvhBrick, IdsNormalsAndBarycentricsFollowTheContract) {
  // One triangle with a user id; the hit point must be (1-u-v) v0 + u v1 + v v2.
  BrickData brick;
  brick.triangles = {{{0, 0, 0}, {2, 0, 0}, {0, 1, 0}}};
  brick.ids = {{3, 17}};
  for (const TriangleTest test : kAllTests) {
    const auto accel = build(brick, test);
    Ray ray;
    ray.origin = {0.5f, 0.25f, 2.0f};
    ray.direction = {0, 0, -0.5f};  // not unit: t is in units of its length
    Hit hit;
    accel->intersect(all_ids(1), &ray, &hit);
    ASSERT_TRUE(hit.is_hit()) << triangle_test_name(test);
    EXPECT_EQ(hit.geometry_id, 3u);
    EXPECT_EQ(hit.primitive_id, 17u);
    EXPECT_FLOAT_EQ(hit.t, 4.0f);
    EXPECT_FLOAT_EQ(hit.u, 0.25f);  // x = 2u
    EXPECT_FLOAT_EQ(hit.v, 0.25f);  // y = v
    // Embree's Ng orientation: cross(v1 - v0, v2 - v0) = +z, whichever side.
    EXPECT_EQ(hit.normal, Vec3f(0, 0, 1));
  }
}

TEST(BvhBrick, SegmentRuleIsTnearExclusiveTfarInclusive) {
  BrickData brick;
  brick.triangles = {{{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}}};
  brick.ids = {{0, 0}};
  for (const TriangleTest test : kAllTests) {
    const auto accel = build(brick, test);
    const auto trace = [&](float tnear, float tfar) {
      Ray ray;
      ray.origin = {0, 0, 1};
      ray.direction = {0, 0, -1};
      ray.tnear = tnear;
      ray.tfar = tfar;
      Hit hit;
      accel->intersect(all_ids(1), &ray, &hit);
      uint8_t occluded = 0;
      accel->occluded(all_ids(1), &ray, &occluded);
      EXPECT_EQ(occluded != 0, hit.is_hit());
      return hit.is_hit();
    };
    EXPECT_TRUE(trace(0.0f, 1.0f)) << triangle_test_name(test);   // tfar exactly at the hit
    EXPECT_FALSE(trace(1.0f, 2.0f)) << triangle_test_name(test);  // tnear exactly at the hit
    EXPECT_FALSE(trace(0.0f, std::nextafter(1.0f, 0.0f))) << triangle_test_name(test);
    EXPECT_TRUE(trace(std::nextafter(1.0f, 0.0f), 2.0f)) << triangle_test_name(test);
    EXPECT_FALSE(trace(0.5f, 0.5f)) << triangle_test_name(test);
  }
}

TEST(BvhBrick, TiesGoToTheSmallerUserIdWhateverTheOrder) {
  // Three copies of one triangle with ids in scrambled order, plus a hit the
  // ray brings from another brick at the same t.
  BrickData brick;
  const Triangle tri{{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}};
  brick.triangles = {tri, tri, tri};
  brick.ids = {{1, 5}, {0, 9}, {1, 2}};
  for (const TriangleTest test : kAllTests) {
    for (uint32_t leaf : {1u, 8u}) {
      BinnedSahBuilder::Config builder;
      builder.max_leaf_size = leaf;
      const auto accel = build(brick, test, builder);
      Ray ray;
      ray.origin = {0.1f, 0.1f, 1};
      ray.direction = {0, 0, -1};
      Hit hit;
      accel->intersect(all_ids(1), &ray, &hit);
      EXPECT_EQ(hit.geometry_id, 0u);
      EXPECT_EQ(hit.primitive_id, 9u);
      Hit earlier;  // from another brick, same t, smaller id: keeps it
      earlier.t = hit.t;
      earlier.geometry_id = 0;
      earlier.primitive_id = 3;
      accel->intersect(all_ids(1), &ray, &earlier);
      EXPECT_EQ(earlier.primitive_id, 3u);
      Hit later = earlier;  // same t, larger id: replaced
      later.primitive_id = 10;
      accel->intersect(all_ids(1), &ray, &later);
      EXPECT_EQ(later.primitive_id, 9u);
      Hit nearer = earlier;  // nearer: untouched
      nearer.t = 0.5f;
      nearer.primitive_id = 100;
      accel->intersect(all_ids(1), &ray, &nearer);
      EXPECT_EQ(nearer.primitive_id, 100u);
    }
  }
}

TEST(BvhBrick, AxisParallelRaysWithSignedZeroDirections) {
  // A grid of unit squares in z = 0; rays along -z with +0 and -0 in x and y,
  // some starting exactly on a box plane (x = 0).
  BrickData brick;
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) {
      const Vec3f a(static_cast<float>(i), static_cast<float>(j), 0);
      brick.triangles.push_back({a, a + Vec3f(1, 0, 0), a + Vec3f(1, 1, 0)});
      brick.triangles.push_back({a, a + Vec3f(1, 1, 0), a + Vec3f(0, 1, 0)});
    }
  }
  for (uint32_t k = 0; k < brick.triangles.size(); ++k) brick.ids.push_back({0, k});
  std::vector<Ray> rays;
  for (const float zero : {0.0f, -0.0f}) {
    for (const float x : {0.0f, 0.5f, 1.0f, 3.25f, 8.0f}) {
      for (const float y : {0.0f, 0.75f, 4.0f, 8.0f}) {
        Ray ray;
        ray.origin = {x, y, 2};
        ray.direction = {zero, zero, -1};
        rays.push_back(ray);
      }
    }
  }
  for (const TriangleTest test : kAllTests) {
    const auto accel = build(brick, test);
    std::vector<Hit> hits(rays.size());
    accel->intersect(all_ids(rays.size()), rays.data(), hits.data());
    for (std::size_t i = 0; i < rays.size(); ++i) {
      EXPECT_TRUE(hits[i].is_hit()) << triangle_test_name(test) << " ray " << i;
      EXPECT_EQ(hits[i].t, 2.0f) << triangle_test_name(test) << " ray " << i;
    }
  }
}

TEST(BvhBrick, AnInPlaceViewOfTheTreeGivesIdenticalAnswers) {
  const BrickData brick = load_brick_from("gen:torus?nu=32&nv=16");
  const auto rays = test_rays(brick, 1000, 8);
  for (const TriangleTest test : kAllTests) {
    const auto accel = build(brick, test);
    auto owner = std::make_shared<const WideBvh>(WideBvh::copy_of(accel->view()));
    const auto loaded = BvhBrickAccel::from_view(owner->view(), owner, test, 0, accel->triangle_count());
    EXPECT_TRUE(loaded->in_place());
    EXPECT_FALSE(accel->in_place());
    EXPECT_EQ(loaded->memory_bytes(), accel->memory_bytes());
    std::vector<Hit> a(rays.size()), b(rays.size());
    accel->intersect(all_ids(rays.size()), rays.data(), a.data());
    loaded->intersect(all_ids(rays.size()), rays.data(), b.data());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)), 0) << triangle_test_name(test);
    std::vector<uint8_t> oa(rays.size(), 0), ob(rays.size(), 0);
    accel->occluded(all_ids(rays.size()), rays.data(), oa.data());
    loaded->occluded(all_ids(rays.size()), rays.data(), ob.data());
    EXPECT_EQ(oa, ob);
  }
}

TEST(BvhBrick, ValidateRejectsStructurallyBrokenTrees) {
  const auto accel = build(load_brick_from("gen:sphere?level=3"), TriangleTest::kWatertight);
  ASSERT_TRUE(accel->view().validate().ok());
  ASSERT_GT(accel->view().nodes.size(), 1u);
  const WideBvh good = WideBvh::copy_of(accel->view());
  const int inner = __builtin_ctz(good.nodes[0].inner_mask);
  const int leaf_node = [&] {
    for (std::size_t k = 0; k < good.nodes.size(); ++k) {
      if (good.nodes[k].leaf_mask != 0) return static_cast<int>(k);
    }
    return -1;
  }();
  ASSERT_GE(leaf_node, 0);
  const int leaf = __builtin_ctz(good.nodes[leaf_node].leaf_mask);
  const auto rejects = [](const WideBvh& bad, const std::string& word) {
    const Status status = bad.view().validate();
    ASSERT_FALSE(status.ok()) << word;
    EXPECT_NE(status.message().find(word), std::string::npos) << status.message();
  };
  WideBvh bad = good;
  bad.nodes[0].child[inner] = 0;  // the root its own child
  rejects(bad, "out of range");
  bad = good;
  bad.nodes[leaf_node].leaf_triangles[leaf] = 255;
  bad.nodes[leaf_node].child[leaf] = static_cast<uint32_t>(bad.view().slot_count() - 3);  // past the slots
  rejects(bad, "leaf");
  bad = good;
  bad.nodes[leaf_node].leaf_triangles[leaf] = 0;  // a leaf of no triangles
  rejects(bad, "leaf");
  bad = good;
  bad.nodes[0].leaf_mask |= bad.nodes[0].inner_mask;  // a child both inner and leaf
  rejects(bad, "masks");
  bad = good;
  bad.nodes.resize(1);  // the root's children out of range
  rejects(bad, "out of range");
  bad = good;
  bad.packets.clear();
  rejects(bad, "leaf");
  // A chain of `levels` nodes, each with the next as its inner child and
  // one leaf: the deepest is at depth `levels`.
  const auto chain = [](uint32_t levels) {
    WideBvh tree;
    tree.nodes.resize(levels);
    for (uint32_t k = 0; k < levels; ++k) {
      WideBvhNode& node = tree.nodes[k];
      node.child[0] = k;
      node.leaf_triangles[0] = 1;
      node.leaf_mask = 1;
      if (k + 1 < levels) {
        node.child[1] = k + 1;
        node.inner_mask = 2;
      }
    }
    tree.packets.resize((levels + kPacketLanes - 1) / kPacketLanes);
    return tree;
  };
  const WideBvh deepest_allowed = chain(kMaxBvhDepth);
  EXPECT_TRUE(deepest_allowed.view().validate().ok()) << deepest_allowed.view().validate().to_string();
  rejects(chain(kMaxBvhDepth + 1), "deeper");
}

TEST(BvhBrick, ReserveBytesBoundsMemoryAndBuildPeak) {
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  std::vector<std::pair<std::string, BrickData>> shapes;
  for (const uint64_t n : {1, 10, 100, 1000, 20000}) {
    shapes.emplace_back("bunny " + std::to_string(n), accel_test::resized(bunny, n));
    shapes.emplace_back("random " + std::to_string(n), accel_test::random_triangles(n, n));
    shapes.emplace_back("degenerate " + std::to_string(n), accel_test::degenerate_heavy(n, n));
  }
  BinnedSahBuilder::Config leaf_one;
  leaf_one.max_leaf_size = 1;
  leaf_one.traversal_cost = 0.01f;  // the most nodes a config can make
  for (const auto& [name, brick] : shapes) {
    for (const auto& builder : {BinnedSahBuilder::Config{}, leaf_one}) {
      const auto accel = build(brick, TriangleTest::kWatertight, builder);
      const uint64_t reserve = BvhBrickAccel::reserve_bytes(brick.triangles.size());
      EXPECT_LE(accel->memory_bytes(), reserve) << name;
      EXPECT_LE(accel->build_peak_bytes(), reserve) << name;
      EXPECT_LE(accel->memory_bytes(), accel->build_peak_bytes()) << name;
      EXPECT_EQ(accel->triangle_count(), brick.triangles.size());
    }
  }
  // With the default config the built bunny takes about 92 B/tri.
  const auto accel = build(bunny, TriangleTest::kWatertight);
  EXPECT_LT(accel->memory_bytes(), 100 * bunny.triangles.size());
}

TEST(BvhBrick, BadBricksAreErrors) {
  BrickData brick = load_brick_from("gen:sphere?level=1");
  brick.ids.pop_back();
  auto accel = BvhBrickAccel::build(std::move(brick), {});
  ASSERT_FALSE(accel.ok());
  EXPECT_EQ(accel.status().code(), StatusCode::kInvalidArgument);
  // An empty brick and a brick of degenerate triangles only are fine and never hit.
  BrickData empty;
  auto built = BvhBrickAccel::build(std::move(empty), {});
  ASSERT_TRUE(built.ok());
  BrickData flat;
  flat.triangles = {{{0, 0, 0}, {1, 1, 1}, {2, 2, 2}}, {{1, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  flat.ids = {{0, 0}, {0, 1}};
  auto degenerate = BvhBrickAccel::build(std::move(flat), {});
  ASSERT_TRUE(degenerate.ok());
  EXPECT_EQ((*degenerate)->triangle_count(), 2u);
  Ray ray;
  ray.origin = {0.5f, 0.5f, -1};
  ray.direction = {0.1f, 0.1f, 1};
  for (const auto* a : {built->get(), degenerate->get()}) {
    Hit hit;
    a->intersect(all_ids(1), &ray, &hit);
    EXPECT_FALSE(hit.is_hit());
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
