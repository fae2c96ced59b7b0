#include "core/accel/bvh/wide_bvh_top_level.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Walks the tree: each non-empty box is a leaf exactly once, under boxes that
// hold it; children follow their parent; empty slots are in no mask.
void expect_well_formed(const std::vector<WideBvhNode>& nodes, const std::vector<Aabb>& boxes) {
  std::vector<int> seen(boxes.size(), 0);
  std::vector<uint32_t> pending{0};
  uint32_t visited = 0;
  while (!pending.empty()) {
    const uint32_t index = pending.back();
    pending.pop_back();
    ++visited;
    const WideBvhNode& node = nodes.at(index);
    EXPECT_EQ(node.inner_mask & node.leaf_mask, 0);
    for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
      const Aabb box = node.box(k);
      if ((node.child_mask() >> k & 1) == 0) {
        EXPECT_TRUE(box.empty()) << "an unused slot has an empty box";
        continue;
      }
      if (node.leaf_mask >> k & 1) {
        EXPECT_EQ(node.leaf_triangles[k], 1);
        ASSERT_LT(node.child[k], boxes.size());
        ++seen[node.child[k]];
        EXPECT_EQ(box, boxes[node.child[k]]);
      } else {
        EXPECT_EQ(node.leaf_triangles[k], 0);
        EXPECT_GT(node.child[k], index);
        const WideBvhNode& inner = nodes.at(node.child[k]);
        for (uint32_t j = 0; j < kWideBvhWidth; ++j) {
          if (inner.child_mask() >> j & 1) {
            EXPECT_TRUE(box.contains(inner.box(j)));
          }
        }
        pending.push_back(node.child[k]);
      }
    }
  }
  EXPECT_EQ(visited, nodes.size()) << "every node reachable";
  for (std::size_t i = 0; i < boxes.size(); ++i) EXPECT_EQ(seen[i], boxes[i].empty() ? 0 : 1) << "box " << i;
}

TEST(WideBvhTopLevel, EveryBoxIsOneLeafUnderBoxesThatHoldIt) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-100.0f, 100.0f);
  for (const std::size_t n : {1u, 2u, 8u, 9u, 64u, 65u, 1000u}) {
    SCOPED_TRACE(n);
    std::vector<Aabb> boxes(n);
    for (Aabb& b : boxes) {
      const Vec3f p(u(rng), u(rng), u(rng));
      b.extend(p);
      b.extend(p + Vec3f(1, 2, 3));
    }
    const std::vector<WideBvhNode> nodes = build_wide_top_level(boxes);
    ASSERT_FALSE(nodes.empty());
    expect_well_formed(nodes, boxes);
    if (n <= kWideBvhWidth) {
      EXPECT_EQ(nodes.size(), 1u) << "a few boxes: one node of leaves";
    }
  }
}

TEST(WideBvhTopLevel, EmptyBoxesAndIdenticalCentresAreHandled) {
  EXPECT_TRUE(build_wide_top_level({}).empty());
  std::vector<Aabb> boxes(3);  // all empty
  EXPECT_TRUE(build_wide_top_level(boxes).empty());
  // 100 identical boxes (equal centres) and one empty one among them.
  boxes.assign(101, Aabb{{0, 0, 0}, {1, 1, 1}});
  boxes[50] = Aabb{};
  const std::vector<WideBvhNode> nodes = build_wide_top_level(boxes);
  expect_well_formed(nodes, boxes);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
