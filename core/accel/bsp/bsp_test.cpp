// The BSP tree against brute force with the same triangle test (bitwise: the
// walk may only change which triangles are tested, never the answer), on
// generated scenes, soups, the bunny and a rotated city of thin slabs, with
// 3, 7 and 13 directions; rays aimed at a closed mesh's vertices and edges
// from inside at offsets up to 1e6 (0 leaks with the watertight test); rays
// lying in, and crossing exactly at, split planes of every direction kind;
// the build's structure (validate, every triangle referenced, budgets, the
// diagonal directions used where they pay) and the factory. A DISABLED_
// measurement compares build and trace figures with the kd-tree.
#include "core/accel/bsp/bsp_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/bsp/bsp_brick.h"
#include "core/accel/bsp/bsp_directions.h"
#include "core/accel/bsp/bsp_tree_builder.h"
#include "core/accel/bsp/bsp_tree_traversal.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/kdtree/kd_tree_brick.h"
#include "core/accel/kdtree/kd_tree_builder.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/accel/kdtree/split_tree_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::bounds_of;
using accel_test::load_brick_from;
using split_tree_test::brute_force;
using split_tree_test::mixed_rays;
using split_tree_test::usable;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 400;
#else
constexpr std::size_t kRays = 3000;
#endif

BspTree build_tree(const BrickData& brick, const BspTreeBuilder::Config& config = {}) {
  const BrickData kept = usable(brick);
  return BspTreeBuilder::build(kept.triangles, kept.ids, config).tree;
}

BspTreeBuilder::Config with_directions(uint32_t directions) {
  BspTreeBuilder::Config config;
  config.directions = directions;
  return config;
}

// A city of thin slabs (walls 0.04 thick, 0.6 wide, 0.3 to 2.3 high) on a
// grid, rotated by `degrees` about the x axis: thin geometry that no axis
// plane separates well.
BrickData rotated_city(uint32_t grid, float degrees, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> height(0.3f, 2.3f), jitter(-0.2f, 0.2f);
  const double angle = degrees * 3.14159265358979323846 / 180.0;
  const double c = std::cos(angle), s = std::sin(angle);
  const auto rotate = [&](const Vec3d& p) { return Vec3f(Vec3d(p.x, c * p.y - s * p.z, s * p.y + c * p.z)); };
  BrickData out;
  for (uint32_t i = 0; i < grid; ++i) {
    for (uint32_t j = 0; j < grid; ++j) {
      const bool along_x = (i + j) % 2 == 0;
      const Vec3d lo(i + jitter(rng), j + jitter(rng), 0.0);
      const Vec3d size(along_x ? 0.6 : 0.04, along_x ? 0.04 : 0.6, height(rng));
      const auto corner = [&](int b) {
        return rotate(
            Vec3d(lo.x + (b & 1 ? size.x : 0), lo.y + (b & 2 ? size.y : 0), lo.z + (b & 4 ? size.z : 0)));
      };
      constexpr int kQuads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                    {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
      for (const auto& q : kQuads) {
        out.triangles.push_back({corner(q[0]), corner(q[1]), corner(q[2])});
        out.triangles.push_back({corner(q[0]), corner(q[2]), corner(q[3])});
      }
    }
  }
  for (uint32_t k = 0; k < out.triangles.size(); ++k) out.ids.push_back({1, k});
  return out;
}

// The tree's walks, for the shared helpers (split_tree_test_util.h).
struct BspWalks {
  template <class Test>
  static bool closest(const BspTreeView& view, const Ray& ray, Hit& hit) {
    return bsp_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const BspTreeView& view, const Ray& ray) {
    return bsp_any_hit<Test>(view, ray);
  }
};

template <class Node>
void expect_every_test_matches(const std::string& what, const SplitTree<Node>& tree,
                               const std::vector<Ray>& rays, std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<BspWalks>(what, tree, rays, min_hits);
}

// How many inner nodes split along each direction.
std::array<uint32_t, kBspDirectionCount> directions_used(const BspTree& tree) {
  std::array<uint32_t, kBspDirectionCount> used{};
  for (const BspNode& node : tree.nodes) {
    if (!node.is_leaf()) ++used[node.direction()];
  }
  return used;
}

TEST(Bsp, MatchesBruteForceOnGeneratedScenesSoupsTheBunnyAndARotatedCity) {
  for (const char* spec :
       {"gen:sphere?level=4", "gen:torus?nu=48&nv=24", "gen:terrain?n=24&size=6&height=0.5"}) {
    const BrickData brick = load_brick_from(spec);
    expect_every_test_matches(spec, build_tree(brick), mixed_rays(brick, kRays, 21), kRays / 10);
  }
  const BrickData random = accel_test::random_triangles(1500, 4);
  expect_every_test_matches("random", build_tree(random), mixed_rays(random, kRays, 22), kRays / 10);
  const BrickData scattered = accel_test::scattered_triangles(3000, 5);
  expect_every_test_matches("scattered", build_tree(scattered), mixed_rays(scattered, kRays, 23), 1);
  const BrickData degenerate = accel_test::degenerate_heavy(3000, 6);
  expect_every_test_matches("degenerate", build_tree(degenerate), mixed_rays(degenerate, kRays, 24), 1);
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  expect_every_test_matches("bunny", build_tree(bunny), mixed_rays(bunny, kRays, 25), kRays / 10);
  const BrickData city = rotated_city(16, 30.0f, 7);
  for (const uint32_t directions : {3u, 7u, 13u}) {
    expect_every_test_matches("city directions=" + std::to_string(directions),
                              build_tree(city, with_directions(directions)), mixed_rays(city, kRays, 26),
                              kRays / 20);
  }
}

TEST(Bsp, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    const BspTree tree = build_tree(sphere);
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, tree, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !bsp_closest_hit<WatertightTriangleTest>(tree.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// A point of the plane n_k . p = s near `near` (exactly on it in float64, or
// nothing): one coordinate the plane's normal uses is solved for.
bool point_on_plane(uint32_t k, float s, const Vec3f& near, Vec3f& out) {
  const auto& n = kBspDirections[k];
  out = near;
  int solve = 0;
  while (n[solve] == 0) ++solve;
  out[solve] = 0.0f;
  out[solve] = static_cast<float>((s - bsp_dot(k, out)) * n[solve]);
  return bsp_dot(k, out) == static_cast<double>(s);
}

// Rays lying in the tree's own split planes of every direction kind (origin
// on the plane, direction in it both ways), and rays from outside crossing a
// split plane exactly at a point of it or at the vertex nearest to it.
TEST(Bsp, RaysInAndThroughSplitPlanesOfEveryDirectionLoseNothing) {
  for (const char* spec : {"gen:terrain?n=16&size=4&height=0", "gen:sphere?level=3", "city"}) {
    const BrickData brick = std::string(spec) == "city" ? rotated_city(8, 30.0f, 3) : load_brick_from(spec);
    const BspTree tree = build_tree(brick);
    const Aabb b = bounds_of(brick);
    std::mt19937_64 rng(5);
    std::vector<Ray> rays;
    std::array<uint32_t, 3> in_plane_by_kind{};  // axis, cube diagonal, face diagonal
    for (const BspNode& node : tree.nodes) {
      if (node.is_leaf()) continue;
      const uint32_t k = node.direction();
      const Vec3d n = bsp_normal(k);
      for (int attempt = 0; attempt < 2; ++attempt) {
        Vec3f p;
        if (!point_on_plane(k, node.split(), accel_test::random_point(rng, b.lo, b.hi), p)) continue;
        for (const Vec3d& along :
             {cross(n, Vec3d(1, 0, 0)), cross(n, Vec3d(0, 1, 0)), cross(n, Vec3d(0, 0, 1))}) {
          if (dot(along, along) == 0.0) continue;
          for (const float sign : {1.0f, -1.0f}) {
            Ray ray;
            ray.origin = p;
            ray.direction = Vec3f(along) * sign;
            rays.push_back(ray);
          }
          ++in_plane_by_kind[k < 3 ? 0 : (k < 7 ? 1 : 2)];
        }
        Ray through;
        through.origin = b.center() + Vec3f(0.3f, 0.7f, 0.2f) * length(b.extent());
        through.direction = p - through.origin;
        rays.push_back(through);
      }
      // The vertex nearest to the plane.
      float nearest = std::numeric_limits<float>::infinity();
      Vec3f vertex;
      for (const Triangle& tri : brick.triangles) {
        for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
          const auto distance = static_cast<float>(std::fabs(bsp_dot(k, v) - node.split()));
          if (distance < nearest) nearest = distance, vertex = v;
        }
      }
      Ray through;
      through.origin = b.center() - Vec3f(0.6f, 0.2f, 0.5f) * length(b.extent());
      through.direction = vertex - through.origin;
      rays.push_back(through);
    }
    ASSERT_GT(rays.size(), 10u) << spec;
    expect_every_test_matches(std::string(spec) + " split planes", tree, rays, 1);
    if (std::string(spec) == "city") {
      for (const uint32_t count : in_plane_by_kind) EXPECT_GT(count, 0u) << "a direction kind unused";
    }
  }
}

TEST(Bsp, TheBuildReferencesEveryTriangleKeepsItsBudgetsAndUsesTheDiagonals) {
  const BrickData city = rotated_city(24, 30.0f, 9);
  for (const uint32_t directions : {3u, 7u, 13u}) {
    const BspTreeBuilder::Result built =
        BspTreeBuilder::build(city.triangles, city.ids, with_directions(directions));
    const BspTree& tree = built.tree;
    ASSERT_TRUE(tree.view().validate().ok());
    std::vector<uint8_t> seen(tree.triangles.size(), 0);
    for (const uint32_t ref : tree.refs) seen[ref] = 1;
    EXPECT_EQ(std::count(seen.begin(), seen.end(), 0), 0);
    const uint64_t n = city.triangles.size();
    EXPECT_LE(tree.refs.size(), BspTreeBuilder::kMaxReferencesPerTriangle * n + 64);
    EXPECT_LE(tree.memory_bytes(), BspTreeBuilder::tree_bytes_bound(n));
    EXPECT_LE(built.peak_bytes, BspTreeBuilder::peak_bytes_bound(n));
    EXPECT_GT(tree.nodes.size(), n / 8);  // it did split
    const auto used = directions_used(tree);
    for (uint32_t k = directions; k < kBspDirectionCount; ++k) EXPECT_EQ(used[k], 0u) << k;
    uint32_t diagonal = 0;
    for (uint32_t k = 3; k < directions; ++k) diagonal += used[k];
    if (directions == 13) {
      EXPECT_GT(diagonal, 0u) << "the rotated city needs diagonals";
    }
  }
  // A depth limit of 1 leaves one leaf with everything.
  BspTreeBuilder::Config shallow;
  shallow.max_depth = 1;
  const BspTree flat = BspTreeBuilder::build(city.triangles, city.ids, shallow).tree;
  ASSERT_EQ(flat.nodes.size(), 1u);
  EXPECT_EQ(flat.refs.size(), city.triangles.size());
}

TEST(Bsp, AViewThatDoesNotHoldTogetherIsAnError) {
  BspTree tree;
  tree.triangles = {Triangle{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  tree.records = {{{0, 0, 1}, 0, 0}};
  tree.refs = {0};
  tree.nodes = {BspNode::inner(4, 0.5f, 2), BspNode::leaf(0, 1), BspNode::leaf(0, 1)};
  EXPECT_TRUE(tree.view().validate().ok());
  tree.nodes = {BspNode::inner(4, 0.5f, 1), BspNode::leaf(0, 1)};  // above child == below child
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {BspNode::inner(4, 0.5f, 7), BspNode::leaf(0, 1), BspNode::leaf(0, 1)};  // out of range
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {BspNode::inner(13, 0.5f, 2), BspNode::leaf(0, 1), BspNode::leaf(0, 1)};  // no such direction
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {BspNode::inner(4, std::nanf(""), 2), BspNode::leaf(0, 1), BspNode::leaf(0, 1)};
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {BspNode::inner(0, 0.5f, 2), BspNode::leaf(0, 1), BspNode::leaf(0, 2)};  // past the refs
  EXPECT_FALSE(tree.view().validate().ok());
  // A chain one deeper than the stack.
  tree.nodes.clear();
  for (uint32_t i = 0; i < kMaxBspDepth; ++i) {
    tree.nodes.push_back(BspNode::inner(i % kBspDirectionCount, 0.5f, 2 * i + 2));
    tree.nodes.push_back(BspNode::leaf(0, 1));
  }
  tree.nodes.push_back(BspNode::leaf(0, 1));  // at depth kMaxBspDepth + 1
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes.resize(2 * (kMaxBspDepth - 1));
  tree.nodes.push_back(BspNode::leaf(0, 1));  // at depth kMaxBspDepth
  EXPECT_TRUE(tree.view().validate().ok());
  tree.nodes = {BspNode::leaf(0, 1)};
  tree.refs = {7};  // no such triangle
  EXPECT_FALSE(tree.view().validate().ok());
}

TEST(Bsp, TheFactoryMakesItByNameAndRejectsBadOptions) {
  auto builder = make_brick_builder("bsp", {});
  ASSERT_TRUE(builder.ok());
  EXPECT_EQ((*builder)->name(), "bsp");
  EXPECT_TRUE(make_brick_builder("bsp", {{"triangle_test", "double"},
                                         {"empty_bonus", "0.2"},
                                         {"directions", "7"},
                                         {"max_depth", "20"},
                                         {"traversal_cost", "2"},
                                         {"intersection_cost", "40"}})
                  .ok());
  for (const BrickAccelOptions& bad : std::vector<BrickAccelOptions>{{{"triangle_test", "exact"}},
                                                                     {{"empty_bonus", "1"}},
                                                                     {{"max_depth", "65"}},
                                                                     {{"intersection_cost", "-1"}},
                                                                     {{"traversal_cost", "x"}},
                                                                     {{"directions", "5"}},
                                                                     {{"directions", "13x"}},
                                                                     {{"bins", "8"}}}) {
    const auto made = make_brick_builder("bsp", bad);
    ASSERT_FALSE(made.ok()) << bad.begin()->first;
    EXPECT_NE(made.status().message().find(bad.begin()->first), std::string::npos) << made.status().message();
  }
  // Built through the factory, a brick answers as brute force, within its
  // reservation.
  const BrickData city = rotated_city(8, 30.0f, 11);
  const std::vector<Ray> rays = mixed_rays(city, 500, 31);
  auto accel = (*builder)->build(BrickData(city));
  ASSERT_TRUE(accel.ok());
  const auto& bsp = dynamic_cast<const BspBrickAccel&>(**accel);
  const uint64_t reserved = (*builder)->reserve_bytes(static_cast<uint32_t>(city.triangles.size()));
  EXPECT_LE(bsp.memory_bytes(), reserved);
  EXPECT_LE(bsp.build_peak_bytes(), reserved);
  EXPECT_EQ(bsp.memory_bytes(), bsp.view().nodes.size() * sizeof(BspNode) + bsp.view().refs.size() * 4 +
                                    city.triangles.size() * (sizeof(Triangle) + sizeof(BvhHitRecord)) +
                                    BspBrickAccel::kOverheadBytes);
  std::vector<Hit> got(rays.size());
  (*accel)->intersect(accel_test::all_ids(rays.size()), rays.data(), got.data());
  std::vector<uint8_t> occluded(rays.size(), 0);
  (*accel)->occluded(accel_test::all_ids(rays.size()), rays.data(), occluded.data());
  const BspTree tree = build_tree(city);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Hit want;
    bool any = false;
    brute_force<WatertightTriangleTest>(tree.view(), rays[i], want, any);
    EXPECT_EQ(std::memcmp(&want, &got[i], sizeof(Hit)), 0) << "ray " << i;
    EXPECT_EQ(occluded[i] != 0, any) << "ray " << i;
  }
}

// The triangle tests a tree's closest-hit walk makes, per ray.
struct TestCounter {
  uint64_t tests = 0;
};
thread_local TestCounter* g_counter = nullptr;
struct CountingTest {
  using Prepared = WatertightTriangleTest::Prepared;
  static Prepared prepare(const Ray& ray) { return WatertightTriangleTest::prepare(ray); }
  static bool hit(const Prepared& r, const Triangle& tri, float tnear, float tfar, TriangleHit& out) {
    ++g_counter->tests;
    return WatertightTriangleTest::hit(r, tri, tnear, tfar, out);
  }
};

template <class Closest>
double tests_per_ray(const std::vector<Ray>& rays, Closest&& closest) {
  TestCounter counter;
  g_counter = &counter;
  for (const Ray& ray : rays) {
    Hit hit;
    closest(ray, hit);
  }
  g_counter = nullptr;
  return static_cast<double>(counter.tests) / static_cast<double>(rays.size());
}

// The target of issue 24: on thin geometry at an angle, the diagonal planes
// cut the triangle tests below the kd-tree's.
TEST(Bsp, OnARotatedCityItTestsFewerTrianglesThanTheKdTree) {
  const BrickData city = rotated_city(24, 30.0f, 13);
  const std::vector<Ray> rays = mixed_rays(city, kRays, 41);
  const BspTree bsp = build_tree(city);
  const KdTree kd = KdTreeBuilder::build(city.triangles, city.ids, {}).tree;
  const double bsp_tests = tests_per_ray(
      rays, [&](const Ray& ray, Hit& hit) { bsp_closest_hit<CountingTest>(bsp.view(), ray, hit); });
  const double kd_tests = tests_per_ray(
      rays, [&](const Ray& ray, Hit& hit) { kd_closest_hit<CountingTest>(kd.view(), ray, hit); });
  EXPECT_LT(bsp_tests, kd_tests);
  std::printf("rotated city: %.2f triangle tests per ray (bsp) vs %.2f (kd-tree)\n", bsp_tests, kd_tests);
}

double median3(std::array<double, 3> v) {
  std::sort(v.begin(), v.end());
  return v[1];
}

// Not a test: build and trace figures against the kd-tree (medians of 3),
// for the benchmark notes. Run with --gtest_also_run_disabled_tests
// --gtest_filter='*MeasureAgainstTheKdTree'; OUTCORE_BSP_MEASURE_GRID sets
// the city's grid (default 140: 235k triangles).
TEST(Bsp, DISABLED_MeasureAgainstTheKdTree) {
  const char* grid_env = std::getenv("OUTCORE_BSP_MEASURE_GRID");
  const uint32_t grid = grid_env != nullptr ? static_cast<uint32_t>(std::atoi(grid_env)) : 140;
  struct Scene {
    std::string name;
    BrickData brick;
  };
  std::vector<Scene> scenes;
  scenes.push_back({"bunny", usable(load_brick_from(accel_test::bunny_path()))});
  scenes.push_back({"city rotated 30deg", rotated_city(grid, 30.0f, 17)});
  for (const Scene& scene : scenes) {
    const std::vector<Ray> rays = mixed_rays(scene.brick, 1000000, 51);
    const std::vector<uint32_t> ids = accel_test::all_ids(rays.size());
    const std::vector<Ray> sample(rays.begin(), rays.begin() + 100000);
    for (const char* name : {"kdtree", "bsp"}) {
      auto builder = make_brick_builder(name, {});
      ASSERT_TRUE(builder.ok());
      std::array<double, 3> build_s{}, trace_s{};
      std::unique_ptr<BrickAccel> accel;
      for (int run = 0; run < 3; ++run) {
        auto built = (*builder)->build(BrickData(scene.brick));
        ASSERT_TRUE(built.ok());
        accel = std::move(*built);
        build_s[run] = accel->build_seconds();
      }
      for (int run = 0; run < 3; ++run) {
        std::vector<Hit> hits(rays.size());
        const auto start = std::chrono::steady_clock::now();
        accel->intersect(ids, rays.data(), hits.data());
        trace_s[run] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      }
      double tests = 0;
      if (std::string(name) == "bsp") {
        const BspTreeView view = dynamic_cast<const BspBrickAccel&>(*accel).view();
        tests = tests_per_ray(
            sample, [&](const Ray& ray, Hit& hit) { bsp_closest_hit<CountingTest>(view, ray, hit); });
      } else {
        const KdTreeView view = dynamic_cast<const KdTreeBrickAccel&>(*accel).view();
        tests = tests_per_ray(
            sample, [&](const Ray& ray, Hit& hit) { kd_closest_hit<CountingTest>(view, ray, hit); });
      }
      const double n = static_cast<double>(scene.brick.triangles.size());
      std::printf("%-20s %-7s %8.0f tris  build %7.3f s  %6.1f B/tri  trace 1M %6.3f s  %6.2f tests/ray\n",
                  scene.name.c_str(), name, n, median3(build_s),
                  static_cast<double>(accel->memory_bytes()) / n, median3(trace_s), tests);
    }
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
