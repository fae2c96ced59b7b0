// The octree against brute force with the same triangle test (bitwise: the
// walk may only change which triangles are tested, never the answer), on
// generated scenes, soups, the bunny, rays aimed at a closed mesh's vertices
// and edges from inside at offsets up to 1e6 (0 leaks with the watertight
// test), rays lying in its nodes' middle planes and through their centres
// (where eight cells meet); the build's budgets and stopping rule;
// validate(); the factory. The serialiser is tested with the split-plane
// trees' (kdtree/split_tree_serializer_test.cpp).
#include "core/accel/octree/octree.h"

#include <gtest/gtest.h>

#include <cstring>
#include <set>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/kdtree/split_tree_test_util.h"
#include "core/accel/octree/octree_brick.h"
#include "core/accel/octree/octree_builder.h"
#include "core/accel/octree/octree_traversal.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::load_brick_from;
using split_tree_test::brute_force;
using split_tree_test::mixed_rays;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 400;
#else
constexpr std::size_t kRays = 3000;
#endif

Octree build_tree(const BrickData& brick, const OctreeBuilder::Config& config = {}) {
  const BrickData kept = split_tree_test::usable(brick);
  return OctreeBuilder::build(kept.triangles, kept.ids, config).tree;
}

struct OctreeWalks {
  template <class Test>
  static bool closest(const OctreeView& view, const Ray& ray, Hit& hit) {
    return octree_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const OctreeView& view, const Ray& ray) {
    return octree_any_hit<Test>(view, ray);
  }
};

void expect_every_test_matches(const std::string& what, const Octree& tree, const std::vector<Ray>& rays,
                               std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<OctreeWalks>(what, tree, rays, min_hits);
}

OctreeBuilder::Config leaves_of(uint32_t size) {
  OctreeBuilder::Config config;
  config.max_leaf_size = size;
  return config;
}

TEST(Octree, MatchesBruteForceOnGeneratedScenesSoupsAndTheBunny) {
  split_tree_test::expect_every_test_matches_on_the_usual_scenes<OctreeWalks>(
      [](const BrickData& brick) { return build_tree(brick); }, kRays);
  const BrickData torus = load_brick_from("gen:torus?nu=48&nv=24");
  expect_every_test_matches("torus, leaves of 1", build_tree(torus, leaves_of(1)),
                            mixed_rays(torus, kRays, 20), kRays / 10);
}

TEST(Octree, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    const Octree tree = build_tree(sphere, leaves_of(2));
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, tree, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !octree_closest_hit<WatertightTriangleTest>(tree.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// Every inner node's box, from the root down.
std::vector<Aabb> inner_boxes(const Octree& tree) {
  std::vector<Aabb> boxes;
  std::vector<std::pair<uint32_t, Aabb>> pending{{0u, tree.bounds}};
  while (!pending.empty()) {
    const auto [index, box] = pending.back();
    pending.pop_back();
    const OctreeNode& node = tree.nodes[index];
    if (node.is_leaf()) continue;
    boxes.push_back(box);
    const Vec3f middle = octree_middle(box);
    for (uint32_t k = 0; k < 8; ++k)
      pending.emplace_back(node.first_child() + k, octree_child_box(box, middle, k));
  }
  return boxes;
}

// Rays in nodes' middle planes (parallel to an axis, and tilted within the
// plane), along the lines where two middle planes meet, and through node
// centres along diagonals (eight cells meet there), on a flat terrain whose
// vertices lie on the planes and on a sphere.
TEST(Octree, RaysInMiddlePlanesAndThroughNodeCentresLoseNothing) {
  for (const char* spec :
       {"gen:terrain?n=16&size=4&height=0", "gen:terrain?n=12&size=4&height=0.7", "gen:sphere?level=3"}) {
    const BrickData brick = load_brick_from(spec);
    const Octree tree = build_tree(brick, leaves_of(2));
    const Aabb b = tree.bounds;
    std::vector<Ray> rays;
    for (const Aabb& box : inner_boxes(tree)) {
      if (rays.size() > 4000) break;
      const Vec3f middle = octree_middle(box);
      for (int axis = 0; axis < 3; ++axis) {
        for (int other = 0; other < 3; ++other) {
          if (other == axis) continue;
          Ray in_plane;
          in_plane.origin = box.center() + Vec3f(0.013f, -0.021f, 0.017f) * length(box.extent());
          in_plane.origin[axis] = middle[axis];
          in_plane.origin[other] = b.lo[other] - 1.0f;
          in_plane.direction = {0, 0, 0};
          in_plane.direction[other] = 1.0f;
          rays.push_back(in_plane);
          Ray tilted = in_plane;
          tilted.direction[3 - axis - other] = 0.37f;
          rays.push_back(tilted);
          Ray line = in_plane;  // in two middle planes at once
          line.origin[3 - axis - other] = middle[3 - axis - other];
          rays.push_back(line);
        }
      }
      for (const Vec3f& direction :
           {Vec3f(1, 1, 1), Vec3f(-1, 1, -1), Vec3f(box.extent().x, -box.extent().y, 0)}) {
        Ray diagonal;
        diagonal.origin = middle - direction * 3.0f;
        diagonal.direction = direction;
        rays.push_back(diagonal);
      }
    }
    for (std::size_t t = 0; t < brick.triangles.size(); t += 3) {
      Ray down;
      down.origin = brick.triangles[t].v0 + Vec3f(0, 0, length(b.extent()) + 1.0f);
      down.direction = {0, 0, -1};
      rays.push_back(down);
    }
    ASSERT_GT(rays.size(), 20u) << spec;
    expect_every_test_matches(std::string(spec) + " middle planes", tree, rays, 1);
  }
}

TEST(Octree, TheBuildReferencesEveryTriangleKeepsItsBudgetsAndStopsWhereACutWouldCopyEverything) {
  const BrickData bunny = split_tree_test::usable(load_brick_from(accel_test::bunny_path()));
  const auto n = bunny.triangles.size();
  const auto built = OctreeBuilder::build(bunny.triangles, bunny.ids, {});
  const Octree& tree = built.tree;
  ASSERT_TRUE(tree.view().validate().ok());
  EXPECT_GT(tree.nodes.size(), 1000u);
  EXPECT_LE(tree.refs.size(), OctreeBuilder::references_cap(n));
  EXPECT_LE(tree.memory_bytes(), OctreeBuilder::tree_bytes_bound(n));
  EXPECT_LE(built.peak_bytes, OctreeBuilder::peak_bytes_bound(n));
  EXPECT_EQ(std::set<uint32_t>(tree.refs.begin(), tree.refs.end()).size(), n);
  uint32_t largest_leaf = 0;
  for (const OctreeNode& node : tree.nodes) {
    if (node.is_leaf()) largest_leaf = std::max(largest_leaf, node.count());
  }
  EXPECT_LE(largest_leaf, 64u);
  // Triangles that all pass through the box's centre: a cut would copy them
  // into every child, so the root stays a leaf.
  BrickData star;
  for (uint32_t k = 0; k < 40; ++k) {
    const float s = static_cast<float>(k + 1);
    star.triangles.push_back(Triangle{{-s, -1, -s}, {s, 1, -s}, {0, 0, s}});
    star.ids.push_back({0, k});
  }
  const Octree one = build_tree(star);
  EXPECT_EQ(one.nodes.size(), 1u);
  EXPECT_EQ(one.refs.size(), 40u);
  // The depth limit: automatic, and as given.
  EXPECT_EQ(OctreeBuilder::depth_limit({}, 69451), 9u);
  OctreeBuilder::Config shallow;
  shallow.max_depth = 1;
  EXPECT_EQ(build_tree(bunny, shallow).nodes.size(), 9u);
}

TEST(Octree, AViewThatDoesNotHoldTogetherIsAnError) {
  Octree tree = build_tree(load_brick_from("gen:sphere?level=2"));
  ASSERT_TRUE(tree.view().validate().ok());
  Octree bad = tree;
  bad.nodes[0] = OctreeNode::inner(0);  // its own child
  EXPECT_FALSE(bad.view().validate().ok());
  bad = tree;
  bad.nodes[0] = OctreeNode::inner(static_cast<uint32_t>(tree.nodes.size()) - 4);  // children past the end
  EXPECT_FALSE(bad.view().validate().ok());
  bad = tree;
  bad.nodes.back() = OctreeNode::leaf(static_cast<uint32_t>(tree.refs.size()), 1);  // past the refs
  EXPECT_FALSE(bad.view().validate().ok());
}

TEST(Octree, TheFactoryMakesItByNameAndRejectsBadOptions) {
  const BrickData sphere = load_brick_from("gen:sphere?level=3");
  split_tree_test::expect_the_factory_makes(
      "octree", {{"triangle_test", "double"}, {"max_leaf_size", "4"}, {"max_depth", "12"}},
      {{{"triangle_test", "exact"}},
       {{"max_leaf_size", "0"}},
       {{"max_depth", "24"}},
       {{"max_depth", "deep"}},
       {{"cells_per_triangle", "2"}}},
      sphere, build_tree(sphere), 50);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
