#include "core/accel/bvh/binned_sah_builder.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/accel/accel_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Every triangle in exactly one leaf, boxes containing what is below them,
// depth within bounds, leaves no larger than allowed.
void expect_well_formed(const std::vector<Triangle>& tris, const BinnedSahBuilder::Result& r,
                        const BinnedSahBuilder::Config& config) {
  ASSERT_EQ(r.order.size(), tris.size());
  std::vector<int> seen(tris.size(), 0);
  for (const uint32_t k : r.order) ++seen[k];
  for (const int s : seen) EXPECT_EQ(s, 1);
  std::vector<int> covered(tris.size(), 0);
  struct Item {
    uint32_t node, depth;
  };
  std::vector<Item> stack{{0, 1}};
  uint32_t deepest = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    deepest = std::max(deepest, item.depth);
    const BvhNode& node = r.nodes[item.node];
    if (node.is_leaf()) {
      EXPECT_LE(node.count, config.max_leaf_size);
      for (uint32_t j = node.index; j < node.index + node.count; ++j) {
        ++covered[j];
        EXPECT_TRUE(node.bounds.contains(tris[r.order[j]].bounds()));
      }
      continue;
    }
    for (uint32_t c = 0; c < 2; ++c) {
      EXPECT_TRUE(node.bounds.contains(r.nodes[node.index + c].bounds));
      stack.push_back({node.index + c, item.depth + 1});
    }
  }
  for (const int c : covered) EXPECT_EQ(c, 1);
  EXPECT_LE(deepest, kMaxBvhDepth);
  EXPECT_EQ(r.nodes.capacity(), r.nodes.size());
  EXPECT_LE(r.peak_bytes, BinnedSahBuilder::peak_bytes_bound(tris.size()));
}

TEST(BinnedSahBuilder, BuildsWellFormedDeterministicTrees) {
  const BrickData bunny = accel_test::load_brick_from(accel_test::bunny_path());
  for (const auto& tris : {bunny.triangles, accel_test::random_triangles(3000, 1).triangles,
                           accel_test::degenerate_heavy(3000, 2).triangles}) {
    for (const uint32_t leaf : {1u, 4u, 8u}) {
      BinnedSahBuilder::Config config;
      config.max_leaf_size = leaf;
      const auto r = BinnedSahBuilder::build(tris, config);
      expect_well_formed(tris, r, config);
      const auto again = BinnedSahBuilder::build(tris, config);
      EXPECT_EQ(again.order, r.order);
      ASSERT_EQ(again.nodes.size(), r.nodes.size());
    }
  }
}

TEST(BinnedSahBuilder, CoincidentCentroidsAndPathologicalSizesStayWithinTheDepthLimit) {
  // 5000 copies of one triangle: no bin separates them, median splits do.
  std::vector<Triangle> same(5000, Triangle{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  BinnedSahBuilder::Config config;
  expect_well_formed(same, BinnedSahBuilder::build(same, config), config);
  // Nested triangles shrinking geometrically: SAH alone would make a chain.
  std::vector<Triangle> nested;
  for (int k = 0; k < 3000; ++k) {
    const float s = std::ldexp(1.0f, -(k % 120));
    nested.push_back({{0, 0, 0}, {s, 0, 0}, {0, s, 0}});
  }
  config.max_leaf_size = 1;
  expect_well_formed(nested, BinnedSahBuilder::build(nested, config), config);
  EXPECT_TRUE(BinnedSahBuilder::build({}, config).nodes.empty());
}

TEST(BinnedSahBuilder, ConfigValidationNamesTheField) {
  BinnedSahBuilder::Config config;
  EXPECT_TRUE(config.validate().ok());
  config.bin_count = 1;
  EXPECT_NE(config.validate().message().find("bins"), std::string::npos);
  config = {};
  config.max_leaf_size = 0;
  EXPECT_NE(config.validate().message().find("max_leaf_size"), std::string::npos);
  config = {};
  config.traversal_cost = -1;
  EXPECT_NE(config.validate().message().find("traversal_cost"), std::string::npos);
  config = {};
  config.intersection_cost = 0;
  EXPECT_NE(config.validate().message().find("intersection_cost"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
