#include "core/accel/bvh/binned_sah_builder.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/binned_sah_split.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// The builder as first written, kept as the simple reference: scalar binning
// and partitions of an index array, each node's boxes recomputed from its
// triangles. The same decisions (binned_sah_split.h) on the same values, so
// the fast builder must make exactly this tree.
struct ReferenceTree {
  std::vector<BvhNode> nodes;
  std::vector<uint32_t> order;
};

ReferenceTree reference_build(const std::vector<Triangle>& tris, const BinnedSahBuilder::Config& config) {
  using binned_sah::BinScale;
  ReferenceTree tree;
  const auto n = static_cast<uint32_t>(tris.size());
  if (n == 0) return tree;
  std::vector<Vec3f> centroids(n);
  std::vector<Aabb> bounds(n);
  for (uint32_t k = 0; k < n; ++k) {
    centroids[k] = tris[k].centroid();
    bounds[k] = tris[k].bounds();
    tree.order.push_back(k);
  }
  const uint32_t bins = config.bin_count;
  std::vector<Aabb> bin_bounds(3 * bins);
  std::vector<uint32_t> bin_counts(3 * bins);
  std::vector<double> right_cost(bins);
  struct Task {
    uint32_t node, begin, end, depth;
  };
  std::vector<Task> stack{{0, 0, n, 1}};
  tree.nodes.emplace_back();
  std::vector<uint32_t>& order = tree.order;
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    const uint32_t count = task.end - task.begin;
    Aabb box, centroid_box;
    for (uint32_t j = task.begin; j < task.end; ++j) {
      box.extend(bounds[order[j]]);
      centroid_box.extend(centroids[order[j]]);
    }
    tree.nodes[task.node].bounds = box;
    if (count == 1 || (count <= config.max_leaf_size && count <= 8)) {
      tree.nodes[task.node].index = task.begin;
      tree.nodes[task.node].count = count;
      continue;
    }
    const BinScale scale(centroid_box, bins);
    binned_sah::BinnedSplit best;
    if (task.depth < kMaxBvhDepth - 33) {
      std::fill(bin_bounds.begin(), bin_bounds.end(), Aabb{});
      std::fill(bin_counts.begin(), bin_counts.end(), 0u);
      for (uint32_t j = task.begin; j < task.end; ++j) {
        for (int a = 0; a < 3; ++a) {
          if (!scale.usable[a]) continue;
          const uint32_t bin = a * bins + scale.bin_of(centroids[order[j]][a], a);
          bin_bounds[bin].extend(bounds[order[j]]);
          ++bin_counts[bin];
        }
      }
      std::vector<binned_sah::Box4> boxes;
      for (const Aabb& b : bin_bounds) boxes.push_back(binned_sah::Box4::of(b));
      best = binned_sah::cheapest_split(boxes.data(), bin_counts.data(), scale, count, box, config,
                                        right_cost.data());
    }
    if (count <= config.max_leaf_size &&
        (best.axis < 0 || double{config.intersection_cost} * count <= best.cost)) {
      tree.nodes[task.node].index = task.begin;
      tree.nodes[task.node].count = count;
      continue;
    }
    uint32_t mid;
    if (best.axis >= 0) {
      mid = static_cast<uint32_t>(
          std::stable_partition(
              order.begin() + task.begin, order.begin() + task.end,
              [&](uint32_t k) { return scale.bin_of(centroids[k][best.axis], best.axis) < best.bin; }) -
          order.begin());
    } else {
      const int axis = centroid_box.largest_axis();
      mid = task.begin + count / 2;
      std::nth_element(order.begin() + task.begin, order.begin() + mid, order.begin() + task.end,
                       [&](uint32_t x, uint32_t y) {
                         const float cx = centroids[x][axis], cy = centroids[y][axis];
                         return cx < cy || (cx == cy && x < y);
                       });
    }
    const auto child = static_cast<uint32_t>(tree.nodes.size());
    tree.nodes[task.node].index = child;
    tree.nodes[task.node].count = 0;
    tree.nodes.emplace_back();
    tree.nodes.emplace_back();
    stack.push_back({child + 1, mid, task.end, task.depth + 1});
    stack.push_back({child, task.begin, mid, task.depth + 1});
  }
  return tree;
}

// The same nodes (boxes, children, leaf ranges) and the same triangles in
// each leaf (in any order: only the order inside a leaf may differ).
void expect_same_tree(const ReferenceTree& expected, const BinnedSahBuilder::Result& r) {
  ASSERT_EQ(r.nodes.size(), expected.nodes.size());
  ASSERT_EQ(r.order.size(), expected.order.size());
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    const BvhNode& a = r.nodes[i];
    const BvhNode& b = expected.nodes[i];
    ASSERT_TRUE(a.bounds == b.bounds) << "node " << i;
    ASSERT_EQ(a.index, b.index) << "node " << i;
    ASSERT_EQ(a.count, b.count) << "node " << i;
    if (!a.is_leaf()) continue;
    std::vector<uint32_t> got(r.order.begin() + a.index, r.order.begin() + a.index + a.count);
    std::vector<uint32_t> want(expected.order.begin() + b.index, expected.order.begin() + b.index + b.count);
    std::sort(got.begin(), got.end());
    std::sort(want.begin(), want.end());
    ASSERT_EQ(got, want) << "leaf " << i;
  }
}

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

TEST(BinnedSahBuilder, MakesExactlyTheSimpleReferenceBuildsTree) {
  const BrickData bunny = accel_test::load_brick_from(accel_test::bunny_path());
  std::vector<Triangle> same(700, Triangle{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  std::vector<Triangle> nested;
  for (int k = 0; k < 1500; ++k) {
    const float s = std::ldexp(1.0f, -(k % 120));
    nested.push_back({{0, 0, 0}, {s, 0, 0}, {0, s, 0}});
  }
  // Far from the origin and tiny: centroid spreads that do not scale to bins.
  std::vector<Triangle> far = accel_test::random_triangles(2000, 7).triangles;
  for (Triangle& t : far) {
    for (Vec3f* v : {&t.v0, &t.v1, &t.v2}) *v = *v * 1e-6f + Vec3f{1e6f, -3e5f, 7e4f};
  }
  const std::vector<Triangle> random = accel_test::random_triangles(4000, 3).triangles;
  const std::vector<Triangle> degenerate = accel_test::degenerate_heavy(3000, 4).triangles;
  for (const std::vector<Triangle>* input : std::initializer_list<const std::vector<Triangle>*>{
           &bunny.triangles, &same, &nested, &far, &random, &degenerate}) {
    for (const uint32_t bins : {2u, 16u, 256u}) {
      for (const uint32_t leaf : {1u, 8u, 40u}) {
        BinnedSahBuilder::Config config;
        config.bin_count = bins;
        config.max_leaf_size = leaf;
        SCOPED_TRACE("bins " + std::to_string(bins) + ", leaf " + std::to_string(leaf) + ", " +
                     std::to_string(input->size()) + " triangles");
        expect_same_tree(reference_build(*input, config), BinnedSahBuilder::build(*input, config));
      }
    }
  }
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
