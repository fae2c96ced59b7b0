// The quadtree against brute force with the same triangle test (bitwise: the
// walk may only change which triangles are tested, never the answer), on
// generated scenes, soups, the bunny, terrains lying along each axis, rays
// aimed at a closed mesh's vertices and edges from inside at offsets up to
// 1e6 (0 leaks with the watertight test), rays lying in its nodes' middle
// planes, along the lines where two meet (four columns), and grazing the
// columns' height bounds; the choice of axes, each node's height bound, the
// build's budgets and stopping rule; validate(); the factory. The
// serialiser is tested with the split-plane trees'
// (kdtree/split_tree_serializer_test.cpp).
#include "core/accel/quadtree/quadtree.h"

#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/kdtree/split_tree_test_util.h"
#include "core/accel/quadtree/quadtree_brick.h"
#include "core/accel/quadtree/quadtree_builder.h"
#include "core/accel/quadtree/quadtree_traversal.h"

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

Quadtree build_tree(const BrickData& brick, const QuadtreeBuilder::Config& config = {}) {
  const BrickData kept = split_tree_test::usable(brick);
  return QuadtreeBuilder::build(kept.triangles, kept.ids, config).tree;
}

struct QuadtreeWalks {
  template <class Test>
  static bool closest(const QuadtreeView& view, const Ray& ray, Hit& hit) {
    return quadtree_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const QuadtreeView& view, const Ray& ray) {
    return quadtree_any_hit<Test>(view, ray);
  }
};

void expect_every_test_matches(const std::string& what, const Quadtree& tree, const std::vector<Ray>& rays,
                               std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<QuadtreeWalks>(what, tree, rays, min_hits);
}

QuadtreeBuilder::Config leaves_of(uint32_t size) {
  QuadtreeBuilder::Config config;
  config.max_leaf_size = size;
  return config;
}

// The brick with its coordinates rotated: x, y, z -> y, z, x (`turns` times).
BrickData rotated(BrickData brick, int turns) {
  auto turn = [&](Vec3f p) {
    for (int t = 0; t < turns; ++t) p = {p.y, p.z, p.x};
    return p;
  };
  for (Triangle& tri : brick.triangles) tri = {turn(tri.v0), turn(tri.v1), turn(tri.v2)};
  return brick;
}

TEST(Quadtree, MatchesBruteForceOnGeneratedScenesSoupsAndTheBunny) {
  split_tree_test::expect_every_test_matches_on_the_usual_scenes<QuadtreeWalks>(
      [](const BrickData& brick) { return build_tree(brick); }, kRays);
  const BrickData torus = load_brick_from("gen:torus?nu=48&nv=24");
  expect_every_test_matches("torus, leaves of 1", build_tree(torus, leaves_of(1)),
                            mixed_rays(torus, kRays, 20), kRays / 10);
}

TEST(Quadtree, TerrainsAlongEachAxisAreCutInTheirPlaneAndMatchBruteForce) {
  const BrickData terrain = load_brick_from("gen:terrain?n=40&size=10&height=0.8");
  for (int turns = 0; turns < 3; ++turns) {
    const BrickData brick = rotated(terrain, turns);
    const Quadtree tree = build_tree(brick);
    const QuadtreeAxes axes = quadtree_axes(tree.bounds);
    EXPECT_EQ(axes.w, (4 - turns) % 3) << "turns " << turns;  // gen:terrain rises along y
    EXPECT_NE(axes.u, axes.w);
    EXPECT_NE(axes.v, axes.w);
    EXPECT_LT(axes.u, axes.v);
    EXPECT_GT(tree.nodes.size(), 100u);
    expect_every_test_matches("terrain turned " + std::to_string(turns), tree,
                              mixed_rays(brick, kRays, 7 + turns), kRays / 10);
  }
}

TEST(Quadtree, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    const Quadtree tree = build_tree(sphere, leaves_of(2));
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, tree, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !quadtree_closest_hit<WatertightTriangleTest>(tree.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// Every node's box in the plane, from the root down.
std::vector<std::pair<uint32_t, Aabb>> node_boxes(const Quadtree& tree) {
  const QuadtreeAxes axes = quadtree_axes(tree.bounds);
  std::vector<std::pair<uint32_t, Aabb>> boxes;
  std::vector<std::pair<uint32_t, Aabb>> pending{{0u, tree.bounds}};
  while (!pending.empty()) {
    const auto [index, box] = pending.back();
    pending.pop_back();
    boxes.emplace_back(index, box);
    const QuadtreeNode& node = tree.nodes[index];
    if (node.is_leaf()) continue;
    const float mu = quadtree_middle(box, axes.u), mv = quadtree_middle(box, axes.v);
    for (uint32_t k = 0; k < 4; ++k)
      pending.emplace_back(node.first_child() + k, quadtree_child_box(box, axes, mu, mv, k));
  }
  return boxes;
}

// Each node's height bound holds its triangles: every triangle a leaf
// references lies within the extent along w of the leaf and its ancestors.
TEST(Quadtree, EveryNodesHeightBoundHoldsTheTrianglesUnderIt) {
  const BrickData brick = load_brick_from("gen:terrain?n=30&size=10&height=2");
  const Quadtree tree = build_tree(brick);
  const QuadtreeAxes axes = quadtree_axes(tree.bounds);
  std::size_t checked = 0;
  std::vector<std::pair<uint32_t, std::pair<float, float>>> pending{
      {0u, {tree.nodes[0].w_lo, tree.nodes[0].w_hi}}};
  while (!pending.empty()) {
    const auto [index, range] = pending.back();
    pending.pop_back();
    const QuadtreeNode& node = tree.nodes[index];
    if (node.is_empty()) continue;
    EXPECT_LE(range.first, node.w_lo);
    EXPECT_GE(range.second, node.w_hi);
    if (!node.is_leaf()) {
      for (uint32_t k = 0; k < 4; ++k) pending.push_back({node.first_child() + k, {node.w_lo, node.w_hi}});
      continue;
    }
    for (uint32_t r = node.first(); r < node.first() + node.count(); ++r) {
      const Aabb b = tree.triangles[tree.refs[r]].bounds();
      EXPECT_LE(node.w_lo, b.lo[axes.w]);
      EXPECT_GE(node.w_hi, b.hi[axes.w]);
      ++checked;
    }
  }
  EXPECT_GT(checked, brick.triangles.size());
  // A hilly terrain's cells are columns much lower than the brick.
  double leaf_heights = 0;
  std::size_t leaves = 0;
  for (const QuadtreeNode& node : tree.nodes) {
    if (!node.is_leaf() || node.is_empty()) continue;
    leaf_heights += node.w_hi - node.w_lo;
    ++leaves;
  }
  EXPECT_LT(leaf_heights / leaves, 0.25 * tree.bounds.extent()[axes.w]);
}

// Rays in nodes' middle planes (parallel to an axis, and tilted within the
// plane), along the lines where the two middle planes meet (four columns),
// grazing the columns' height bounds (horizontal at a node's w_lo and w_hi,
// and tilted to touch them), and down through vertices, on flat and hilly
// terrains whose vertices lie on the middle lines, and on a sphere.
TEST(Quadtree, RaysInMiddlePlanesWhereColumnsMeetAndAtTheirHeightBoundsLoseNothing) {
  for (const char* spec :
       {"gen:terrain?n=16&size=4&height=0", "gen:terrain?n=12&size=4&height=0.7", "gen:sphere?level=3"}) {
    const BrickData brick = load_brick_from(spec);
    const Quadtree tree = build_tree(brick, leaves_of(2));
    const QuadtreeAxes axes = quadtree_axes(tree.bounds);
    const Aabb b = tree.bounds;
    std::vector<Ray> rays;
    for (const auto& [index, box] : node_boxes(tree)) {
      if (rays.size() > 5000) break;
      const QuadtreeNode& node = tree.nodes[index];
      const float mu = quadtree_middle(box, axes.u), mv = quadtree_middle(box, axes.v);
      const float w_mid = node.is_empty() ? box.center()[axes.w] : 0.5f * (node.w_lo + node.w_hi);
      for (const int axis : {axes.u, axes.v}) {
        const int other = axis == axes.u ? axes.v : axes.u;
        Ray in_plane;
        in_plane.origin = box.center();
        in_plane.origin[axis] = axis == axes.u ? mu : mv;
        in_plane.origin[other] = b.lo[other] - 1.0f;
        in_plane.origin[axes.w] = w_mid;
        in_plane.direction = {0, 0, 0};
        in_plane.direction[other] = 1.0f;
        rays.push_back(in_plane);
        Ray tilted = in_plane;
        tilted.direction[axes.w] = -0.37f;
        tilted.origin[axes.w] = w_mid + 0.37f * (box.center()[other] - tilted.origin[other]);
        rays.push_back(tilted);
      }
      Ray down;  // along the line where the middle planes meet
      down.origin[axes.u] = mu;
      down.origin[axes.v] = mv;
      down.origin[axes.w] = b.hi[axes.w] + 1.0f;
      down.direction[axes.w] = -1.0f;
      rays.push_back(down);
      if (node.is_empty()) continue;
      for (const float height : {node.w_lo, node.w_hi}) {
        Ray level;  // skimming the column's floor or roof
        level.origin = box.center();
        level.origin[axes.w] = height;
        level.origin[axes.u] = b.lo[axes.u] - 1.0f;
        level.direction[axes.u] = 1.0f;
        level.direction[axes.v] = 0.21f;
        rays.push_back(level);
        Ray touching = level;  // reaching the height bound exactly at the box's centre
        touching.direction[axes.w] = -0.1f;
        touching.origin[axes.w] = height + 0.1f * (box.center()[axes.u] - level.origin[axes.u]);
        rays.push_back(touching);
      }
    }
    for (std::size_t t = 0; t < brick.triangles.size(); t += 3) {
      Ray vertical;
      vertical.origin = brick.triangles[t].v0;
      vertical.origin[axes.w] = b.hi[axes.w] + length(b.extent()) + 1.0f;
      vertical.direction[axes.w] = -1.0f;
      rays.push_back(vertical);
    }
    ASSERT_GT(rays.size(), 20u) << spec;
    expect_every_test_matches(std::string(spec) + " middle planes and height bounds", tree, rays, 1);
  }
}

TEST(Quadtree, TheBuildReferencesEveryTriangleKeepsItsBudgetsAndStopsWhereACutWouldCopyEverything) {
  const BrickData terrain = split_tree_test::usable(load_brick_from("gen:terrain?n=200&size=100&height=3"));
  const auto n = terrain.triangles.size();
  const auto built = QuadtreeBuilder::build(terrain.triangles, terrain.ids, {});
  const Quadtree& tree = built.tree;
  ASSERT_TRUE(tree.view().validate().ok());
  EXPECT_GT(tree.nodes.size(), 1000u);
  EXPECT_LE(tree.refs.size(), QuadtreeBuilder::references_cap(n));
  EXPECT_LE(tree.memory_bytes(), QuadtreeBuilder::tree_bytes_bound(n));
  EXPECT_LE(built.peak_bytes, QuadtreeBuilder::peak_bytes_bound(n));
  EXPECT_EQ(std::set<uint32_t>(tree.refs.begin(), tree.refs.end()).size(), n);
  uint32_t largest_leaf = 0;
  for (const QuadtreeNode& node : tree.nodes) {
    if (node.is_leaf()) largest_leaf = std::max(largest_leaf, node.count());
  }
  EXPECT_LE(largest_leaf, 32u);
  // Triangles that all pass through the middle line: a cut would copy them
  // into every child, so the root stays a leaf.
  BrickData star;
  for (uint32_t k = 0; k < 40; ++k) {
    const float s = static_cast<float>(k + 1);
    star.triangles.push_back(Triangle{{-s, -s, 0}, {s, s, 0.5f}, {-s, s, 0.1f}});
    star.ids.push_back({0, k});
  }
  const Quadtree one = build_tree(star);
  EXPECT_EQ(one.nodes.size(), 1u);
  EXPECT_EQ(one.refs.size(), 40u);
  // The depth limit: automatic, and as given.
  EXPECT_EQ(QuadtreeBuilder::depth_limit({}, 80000), 9u);
  QuadtreeBuilder::Config shallow;
  shallow.max_depth = 1;
  EXPECT_EQ(build_tree(terrain, shallow).nodes.size(), 5u);
}

TEST(Quadtree, AViewThatDoesNotHoldTogetherIsAnError) {
  Quadtree tree = build_tree(load_brick_from("gen:terrain?n=20&size=4&height=1"));
  ASSERT_TRUE(tree.view().validate().ok());
  ASSERT_FALSE(tree.nodes[0].is_leaf());
  Quadtree bad = tree;
  bad.nodes[0] = QuadtreeNode::inner(0, 0, 1);  // its own child
  EXPECT_FALSE(bad.view().validate().ok());
  bad = tree;
  bad.nodes[0] = QuadtreeNode::inner(static_cast<uint32_t>(tree.nodes.size()) - 2, 0, 1);  // past the end
  EXPECT_FALSE(bad.view().validate().ok());
  bad = tree;
  bad.nodes.back() = QuadtreeNode::leaf(static_cast<uint32_t>(tree.refs.size()), 1, 0, 1);  // past the refs
  EXPECT_FALSE(bad.view().validate().ok());
  for (const float w : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    bad = tree;
    bad.nodes[1].w_hi = w;  // a height bound that is not finite
    const Status status = bad.view().validate();
    EXPECT_FALSE(status.ok());
    EXPECT_NE(status.message().find("node 1"), std::string::npos) << status.message();
  }
  bad = tree;
  std::swap(bad.nodes[0].w_lo, bad.nodes[0].w_hi);  // upside down
  EXPECT_FALSE(bad.view().validate().ok());
}

TEST(Quadtree, TheFactoryMakesItByNameAndRejectsBadOptions) {
  const BrickData terrain = load_brick_from("gen:terrain?n=30&size=10&height=1");
  split_tree_test::expect_the_factory_makes(
      "quadtree", {{"triangle_test", "double"}, {"max_leaf_size", "4"}, {"max_depth", "12"}},
      {{{"triangle_test", "exact"}},
       {{"max_leaf_size", "0"}},
       {{"max_depth", "24"}},
       {{"max_depth", "deep"}},
       {{"cells_per_triangle", "2"}}},
      terrain, build_tree(terrain), 51);  // more than 50
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
