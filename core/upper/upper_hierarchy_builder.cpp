#include "core/upper/upper_hierarchy_builder.h"

#include <algorithm>
#include <limits>
#include <numeric>

namespace outcore {

namespace {

struct SweepBuilder {
  std::span<const Aabb> bounds;
  std::vector<uint32_t> order;  // brick ids, permuted as the tree splits them
  std::vector<double> right_area;
  UpperHierarchy tree;

  float centroid(uint32_t brick, int axis) const { return bounds[brick].center()[axis]; }

  // Fills nodes[node_index] for order[begin, end).
  void build(uint32_t node_index, size_t begin, size_t end) {
    Aabb box;
    for (size_t i = begin; i < end; ++i) box.extend(bounds[order[i]]);
    UpperNode& node = tree.nodes[node_index];
    node.bounds = box;
    const size_t count = end - begin;
    if (count == 1) {
      node.child_or_brick = order[begin];
      node.is_leaf = 1;
      return;
    }
    double best_cost = std::numeric_limits<double>::infinity();
    int best_axis = -1;
    size_t best_split = begin + count / 2;
    // Coinciding centroids give every split the same cost, and the sweep would
    // peel off one brick per level (a chain as deep as the brick count, built in
    // quadratic time); they are split in the middle, in brick id order, instead.
    Aabb centroids;
    for (size_t i = begin; i < end; ++i) centroids.extend(bounds[order[i]].center());
    const bool centroids_coincide = centroids.extent() == Vec3f(0, 0, 0);
    for (int axis = 0; axis < 3 && !centroids_coincide; ++axis) {
      // Ties broken by brick id so the tree is deterministic.
      std::sort(order.begin() + begin, order.begin() + end, [&](uint32_t a, uint32_t b) {
        const float ca = centroid(a, axis), cb = centroid(b, axis);
        return ca < cb || (ca == cb && a < b);
      });
      Aabb right;
      for (size_t i = end; i-- > begin + 1;) {
        right.extend(bounds[order[i]]);
        right_area[i] = right.half_area();
      }
      Aabb left;
      for (size_t i = begin; i + 1 < end; ++i) {
        left.extend(bounds[order[i]]);
        const double left_count = static_cast<double>(i + 1 - begin);
        const double right_count = static_cast<double>(end - i - 1);
        const double cost = left.half_area() * left_count + right_area[i + 1] * right_count;
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = axis;
          best_split = i + 1;
        }
      }
    }
    if (best_axis < 0) best_axis = 0;
    std::sort(order.begin() + begin, order.begin() + end, [&](uint32_t a, uint32_t b) {
      const float ca = centroid(a, best_axis), cb = centroid(b, best_axis);
      return ca < cb || (ca == cb && a < b);
    });
    const auto left_index = static_cast<uint32_t>(tree.nodes.size());
    tree.nodes[node_index].child_or_brick = left_index;
    tree.nodes[node_index].is_leaf = 0;
    tree.nodes.emplace_back();
    tree.nodes.emplace_back();
    build(left_index, begin, best_split);
    build(left_index + 1, best_split, end);
  }
};

}  // namespace

UpperHierarchy build_upper_hierarchy(std::span<const Aabb> brick_bounds) {
  SweepBuilder builder{brick_bounds, {}, {}, {}};
  if (brick_bounds.empty()) return {};
  builder.order.resize(brick_bounds.size());
  std::iota(builder.order.begin(), builder.order.end(), 0u);
  builder.right_area.resize(brick_bounds.size() + 1);
  builder.tree.nodes.reserve(2 * brick_bounds.size() - 1);
  builder.tree.nodes.emplace_back();
  builder.build(0, 0, brick_bounds.size());
  return std::move(builder.tree);
}

}  // namespace outcore
