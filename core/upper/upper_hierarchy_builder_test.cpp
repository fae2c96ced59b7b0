#include "core/upper/upper_hierarchy_builder.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

Aabb box(Vec3f lo, Vec3f hi) {
  Aabb b;
  b.extend(lo);
  b.extend(hi);
  return b;
}

// Walks the tree from the root: every node is reached exactly once, the leaves
// are exactly the bricks, each once, every leaf contains its brick, every inner
// node contains both children, and the root is the union of all bricks.
void expect_valid_hierarchy(const UpperHierarchy& tree, const std::vector<Aabb>& bricks) {
  const size_t n = bricks.size();
  ASSERT_EQ(tree.nodes.size(), 2 * n - 1);
  std::vector<int> reached(tree.nodes.size(), 0), leaf_of(n, 0);
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    ASSERT_LT(i, tree.nodes.size());
    ASSERT_EQ(reached[i]++, 0) << "node " << i << " reached twice";
    const UpperNode& node = tree.nodes[i];
    if (node.is_leaf) {
      ASSERT_LT(node.child_or_brick, n);
      ++leaf_of[node.child_or_brick];
      EXPECT_TRUE(node.bounds.contains(bricks[node.child_or_brick])) << "leaf " << i;
      continue;
    }
    for (uint32_t c : {node.child_or_brick, node.child_or_brick + 1}) {
      ASSERT_LT(c, tree.nodes.size()) << "node " << i;
      EXPECT_TRUE(node.bounds.contains(tree.nodes[c].bounds)) << "node " << i << " child " << c;
      stack.push_back(c);
    }
  }
  EXPECT_EQ(reached, std::vector<int>(tree.nodes.size(), 1));
  EXPECT_EQ(leaf_of, std::vector<int>(n, 1));
  Aabb all;
  for (const Aabb& b : bricks) all.extend(b);
  EXPECT_EQ(tree.nodes[0].bounds, all);
}

std::vector<Aabb> random_boxes(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> position(-50.0f, 50.0f), size(0.1f, 5.0f);
  std::vector<Aabb> out;
  for (size_t i = 0; i < n; ++i) {
    const Vec3f lo(position(rng), position(rng), position(rng));
    out.push_back(box(lo, lo + Vec3f(size(rng), size(rng), size(rng))));
  }
  return out;
}

uint32_t depth_bound(size_t n) {
  return static_cast<uint32_t>(2.0 * std::log2(static_cast<double>(n)) + 2.0);
}

TEST(UpperHierarchyBuilder, NoBricksGiveAnEmptyHierarchy) {
  const UpperHierarchy tree = build_upper_hierarchy({});
  EXPECT_TRUE(tree.empty());
  EXPECT_EQ(tree.depth(), 0u);
}

TEST(UpperHierarchyBuilder, OneBrickGivesASingleLeafRoot) {
  const std::vector<Aabb> bricks{box({1, 2, 3}, {4, 5, 6})};
  const UpperHierarchy tree = build_upper_hierarchy(bricks);
  ASSERT_EQ(tree.nodes.size(), 1u);
  EXPECT_TRUE(tree.nodes[0].is_leaf);
  EXPECT_EQ(tree.nodes[0].child_or_brick, 0u);
  EXPECT_EQ(tree.nodes[0].bounds, bricks[0]);
  EXPECT_EQ(tree.depth(), 1u);
}

TEST(UpperHierarchyBuilder, NBricksGive2NMinus1NodesWithEachBrickOneLeafAndNestedBounds) {
  for (const size_t n : {size_t{2}, size_t{3}, size_t{7}, size_t{100}, size_t{1000}}) {
    SCOPED_TRACE(n);
    const auto bricks = random_boxes(n, static_cast<uint32_t>(n));
    const UpperHierarchy tree = build_upper_hierarchy(bricks);
    expect_valid_hierarchy(tree, bricks);
    EXPECT_LE(tree.depth(), depth_bound(n));
  }
}

TEST(UpperHierarchyBuilder, GridOfBricksHasLogarithmicDepth) {
  std::vector<Aabb> bricks;
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x)
        bricks.push_back(box(Vec3f(x, y, z) * 2.0f, Vec3f(x, y, z) * 2.0f + Vec3f(2, 2, 2)));
  const UpperHierarchy tree = build_upper_hierarchy(bricks);
  expect_valid_hierarchy(tree, bricks);
  EXPECT_LE(tree.depth(), depth_bound(bricks.size()));
}

TEST(UpperHierarchyBuilder, IsDeterministic) {
  const auto bricks = random_boxes(500, 99);
  EXPECT_EQ(build_upper_hierarchy(bricks).nodes, build_upper_hierarchy(bricks).nodes);
}

// Bricks of one cloud of identical triangles all have the same bounds; the
// tree over them must still be shallow (a chain would be as deep as the brick
// count and cost quadratic time to build).
TEST(UpperHierarchyBuilder, IdenticalBrickBoundsStillGiveLogarithmicDepth) {
  const std::vector<Aabb> bricks(256, box({0, 0, 0}, {1, 1, 1}));
  const UpperHierarchy tree = build_upper_hierarchy(bricks);
  expect_valid_hierarchy(tree, bricks);
  EXPECT_LE(tree.depth(), depth_bound(bricks.size()));
}

TEST(UpperHierarchyBuilder, ManyIdenticalBricksAmongDistinctOnesStillGiveLogarithmicDepth) {
  std::vector<Aabb> bricks(300, box({0, 0, 0}, {1, 1, 1}));
  const auto others = random_boxes(40, 5);
  bricks.insert(bricks.begin() + 100, others.begin(), others.end());
  const UpperHierarchy tree = build_upper_hierarchy(bricks);
  expect_valid_hierarchy(tree, bricks);
  EXPECT_LE(tree.depth(), depth_bound(bricks.size()));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
