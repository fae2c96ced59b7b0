// refit_wide_bvh: after the triangles in a tree's packets move, every child
// box is again exactly the bounds of the triangles below it (checked by
// walking the tree), the surface-area cost follows (higher for a scrambled
// set, unchanged by a uniform scale), and refit_wide_top_level does the same
// for a top level over boxes.
#include "core/accel/bvh/wide_bvh_refit.h"

#include <gtest/gtest.h>

#include <random>

#include "core/accel/bvh/binned_sah_builder.h"
#include "core/accel/bvh/wide_bvh_collapse.h"
#include "core/accel/bvh/wide_bvh_top_level.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

WideBvh build(const std::vector<Triangle>& triangles) {
  std::vector<TriangleId> ids(triangles.size());
  for (uint32_t t = 0; t < ids.size(); ++t) ids[t] = {0, t};
  const auto binary = BinnedSahBuilder::build(triangles, BinnedSahBuilder::Config{});
  return WideBvhCollapser::collapse(binary.nodes, binary.order, triangles, ids).tree;
}

std::vector<Triangle> soup(std::size_t n, uint32_t seed, float spread) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Triangle> t(n);
  for (Triangle& tri : t) {
    const Vec3f c(u(rng) * spread, u(rng) * spread, u(rng) * spread);
    tri = {c, c + Vec3f(u(rng), 0, 0), c + Vec3f(0, u(rng), u(rng))};
  }
  return t;
}

// The bounds of node `i`'s subtree, checking every child box on the way.
Aabb check(const WideBvh& tree, uint32_t i, int& checked) {
  const WideBvhNode& node = tree.nodes[i];
  Aabb all;
  for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
    Aabb below;
    if ((node.inner_mask >> k) & 1u) {
      below = check(tree, node.child[k], checked);
    } else if ((node.leaf_mask >> k) & 1u) {
      for (uint32_t s = node.child[k]; s < node.child[k] + node.leaf_triangles[k]; ++s)
        below.extend(tree.packets[s / kPacketLanes].triangle(s % kPacketLanes).bounds());
    } else {
      continue;
    }
    EXPECT_EQ(node.box(k).lo, below.lo);
    EXPECT_EQ(node.box(k).hi, below.hi);
    ++checked;
    all.extend(below);
  }
  return all;
}

void move_triangles(WideBvh& tree, const std::vector<Triangle>& to) {
  for (TrianglePacket& p : tree.packets) {
    for (uint32_t lane = 0; lane < kPacketLanes; ++lane) {
      if (p.primitive_id[lane] == kInvalidId) continue;
      const Triangle& t = to[p.primitive_id[lane]];
      const Vec3f v[3] = {t.v0, t.v1, t.v2};
      for (int c = 0; c < 3; ++c)
        for (int a = 0; a < 3; ++a) p.coord[3 * c + a][lane] = v[c][a];
    }
  }
}

TEST(WideBvhRefit, BoxesAreExactlyTheBoundsBelowAfterTheTrianglesMove) {
  const std::vector<Triangle> start = soup(5000, 1, 20);
  WideBvh tree = build(start);
  const double built_cost = wide_bvh_sah_cost(tree.nodes);
  EXPECT_GT(built_cost, 1.0);
  // A uniform scale and shift: the cost relative to the root stays.
  std::vector<Triangle> scaled = start;
  for (Triangle& t : scaled)
    t = {t.v0 * 2.0f + Vec3f(5, 0, 0), t.v1 * 2.0f + Vec3f(5, 0, 0), t.v2 * 2.0f + Vec3f(5, 0, 0)};
  move_triangles(tree, scaled);
  refit_wide_bvh(tree);
  int checked = 0;
  check(tree, 0, checked);
  EXPECT_GT(checked, 600);
  EXPECT_NEAR(wide_bvh_sah_cost(tree.nodes), built_cost, 1e-6 * built_cost);
  // Triangles scattered anywhere: boxes still exact, the cost far higher.
  move_triangles(tree, soup(5000, 2, 20));
  refit_wide_bvh(tree);
  checked = 0;
  check(tree, 0, checked);
  EXPECT_GT(wide_bvh_sah_cost(tree.nodes), 1.5 * built_cost);
}

TEST(WideBvhRefit, TheTopLevelFollowsItsBoxes) {
  std::vector<Aabb> boxes(300);
  for (std::size_t i = 0; i < boxes.size(); ++i) boxes[i] = {Vec3f(i, 0, 0), Vec3f(i + 1.0f, 1, 1)};
  std::vector<WideBvhNode> top = build_wide_top_level(boxes);
  for (Aabb& b : boxes) b = {b.lo + Vec3f(0, 3, 0), b.hi + Vec3f(0, 5, 0)};
  refit_wide_top_level(top, boxes);
  Aabb root;
  for (uint32_t k = 0; k < kWideBvhWidth; ++k)
    if ((top[0].child_mask() >> k) & 1u) root.extend(top[0].box(k));
  EXPECT_EQ(root.lo, Vec3f(0, 3, 0));
  EXPECT_EQ(root.hi, Vec3f(300, 6, 1));
  for (const WideBvhNode& node : top)
    for (uint32_t k = 0; k < kWideBvhWidth; ++k)
      if ((node.leaf_mask >> k) & 1u) {
        EXPECT_EQ(node.box(k).lo, boxes[node.child[k]].lo);
        EXPECT_EQ(node.box(k).hi, boxes[node.child[k]].hi);
      }
  EXPECT_TRUE(wide_bvh_sah_cost({}) == 0.0);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
