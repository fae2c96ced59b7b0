#include "core/accel/bvh/binned_sah_builder.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>

namespace outcore {
namespace {

// Below this depth every split is an object median (see the header).
constexpr uint32_t kMedianDepth = kMaxBvhDepth - 33;
constexpr uint32_t kMaxBins = 256;
constexpr uint64_t kScratchBytes = 3 * kMaxBins * (sizeof(Aabb) + sizeof(uint32_t)) + kMaxBins * 16 + 4096;

struct Task {
  uint32_t node, begin, end, depth;
};

struct Split {
  int axis = -1;
  uint32_t bin = 0;  // triangles in bins < bin go left
  double cost = std::numeric_limits<double>::infinity();
};

}  // namespace

Status BinnedSahBuilder::Config::validate() const {
  if (bin_count < 2 || bin_count > kMaxBins) {
    return invalid_argument("bvh: bins must be in 2..256, got " + std::to_string(bin_count));
  }
  if (max_leaf_size < 1 || max_leaf_size > 255) {
    return invalid_argument("bvh: max_leaf_size must be in 1..255, got " + std::to_string(max_leaf_size));
  }
  if (!(traversal_cost > 0.0f) || !std::isfinite(traversal_cost)) {
    return invalid_argument("bvh: traversal_cost must be a positive number, got " +
                            std::to_string(traversal_cost));
  }
  if (!(intersection_cost > 0.0f) || !std::isfinite(intersection_cost)) {
    return invalid_argument("bvh: intersection_cost must be a positive number, got " +
                            std::to_string(intersection_cost));
  }
  return Status::Ok();
}

uint64_t BinnedSahBuilder::peak_bytes_bound(uint64_t n) {
  // centroids + order + nodes reserved for a full binary tree (2n - 1), then
  // order + that + the exact copy (again at most 2n - 1 nodes).
  return kScratchBytes + n * (sizeof(Vec3f) + sizeof(uint32_t)) + 4 * n * sizeof(BvhNode);
}

BinnedSahBuilder::Result BinnedSahBuilder::build(std::span<const Triangle> triangles, const Config& config) {
  assert(config.validate().ok());
  Result result;
  const uint32_t n = static_cast<uint32_t>(triangles.size());
  if (n == 0) return result;
  const uint32_t bins = config.bin_count;

  std::vector<Vec3f> centroids(n);
  for (uint32_t k = 0; k < n; ++k) centroids[k] = triangles[k].centroid();
  std::vector<uint32_t>& order = result.order;
  order.resize(n);
  for (uint32_t k = 0; k < n; ++k) order[k] = k;
  std::vector<BvhNode> nodes;
  nodes.reserve(2 * uint64_t{n} - 1);
  nodes.emplace_back();
  const uint64_t build_bytes = centroids.capacity() * sizeof(Vec3f) + order.capacity() * sizeof(uint32_t) +
                               nodes.capacity() * sizeof(BvhNode) + kScratchBytes;

  std::vector<Aabb> bin_bounds(3 * bins);
  std::vector<uint32_t> bin_counts(3 * bins);
  std::vector<double> right_cost(bins);  // area * count of bins >= b on one axis
  std::vector<Task> stack{{0, 0, n, 1}};
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    const uint32_t count = task.end - task.begin;
    Aabb bounds, centroid_bounds;
    for (uint32_t j = task.begin; j < task.end; ++j) {
      bounds.extend(triangles[order[j]].bounds());
      centroid_bounds.extend(centroids[order[j]]);
    }
    BvhNode& node = nodes[task.node];
    node.bounds = bounds;
    if (count == 1) {
      node.index = task.begin;
      node.count = 1;
      continue;
    }

    // Per-axis bin scale; an axis whose centroids do not spread (or whose
    // spread is too small to scale) offers no split.
    float lo[3], scale[3];
    bool usable[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = centroid_bounds.lo[a];
      const float extent = centroid_bounds.hi[a] - centroid_bounds.lo[a];
      scale[a] = extent > 0.0f ? static_cast<float>(bins) / extent : 0.0f;
      usable[a] = extent > 0.0f && std::isfinite(scale[a]);
    }
    auto bin_of = [&](const Vec3f& c, int a) {
      const float x = (c[a] - lo[a]) * scale[a];
      return std::min(bins - 1, static_cast<uint32_t>(std::max(0.0f, x)));
    };

    Split best;
    if (task.depth < kMedianDepth) {
      std::fill(bin_bounds.begin(), bin_bounds.end(), Aabb{});
      std::fill(bin_counts.begin(), bin_counts.end(), 0u);
      for (uint32_t j = task.begin; j < task.end; ++j) {
        const Aabb b = triangles[order[j]].bounds();
        const Vec3f& c = centroids[order[j]];
        for (int a = 0; a < 3; ++a) {
          if (!usable[a]) continue;
          const uint32_t bin = a * bins + bin_of(c, a);
          bin_bounds[bin].extend(b);
          ++bin_counts[bin];
        }
      }
      const double inv_area = bounds.half_area() > 0.0 ? 1.0 / bounds.half_area() : 0.0;
      for (int a = 0; a < 3; ++a) {
        if (!usable[a]) continue;
        const Aabb* ab = &bin_bounds[a * bins];
        const uint32_t* ac = &bin_counts[a * bins];
        Aabb right;
        uint32_t right_count = 0;
        for (uint32_t b = bins - 1; b > 0; --b) {
          right.extend(ab[b]);
          right_count += ac[b];
          right_cost[b] = right.half_area() * right_count;
        }
        Aabb left;
        uint32_t left_count = 0;
        for (uint32_t b = 1; b < bins; ++b) {
          left.extend(ab[b - 1]);
          left_count += ac[b - 1];
          if (left_count == 0 || left_count == count) continue;
          const double cost = config.traversal_cost + config.intersection_cost * inv_area *
                                                          (left.half_area() * left_count + right_cost[b]);
          if (cost < best.cost) best = {a, b, cost};
        }
      }
    }
    const double leaf_cost = double{config.intersection_cost} * count;
    if (count <= config.max_leaf_size && (best.axis < 0 || leaf_cost <= best.cost)) {
      node.index = task.begin;
      node.count = count;
      continue;
    }

    uint32_t mid;
    if (best.axis >= 0) {
      const auto first = order.begin() + task.begin, last = order.begin() + task.end;
      mid = static_cast<uint32_t>(
          std::partition(first, last,
                         [&](uint32_t k) { return bin_of(centroids[k], best.axis) < best.bin; }) -
          order.begin());
    } else {
      // Object median along the widest centroid spread (index order when the
      // centroids coincide): always two non-empty halves.
      const int axis = centroid_bounds.largest_axis();
      mid = task.begin + count / 2;
      std::nth_element(order.begin() + task.begin, order.begin() + mid, order.begin() + task.end,
                       [&](uint32_t x, uint32_t y) {
                         const float cx = centroids[x][axis], cy = centroids[y][axis];
                         return cx < cy || (cx == cy && x < y);
                       });
    }
    assert(mid > task.begin && mid < task.end);
    const uint32_t child = static_cast<uint32_t>(nodes.size());
    node.index = child;
    node.count = 0;
    nodes.emplace_back();  // no reallocation: reserved for a full tree
    nodes.emplace_back();
    stack.push_back({child + 1, mid, task.end, task.depth + 1});
    stack.push_back({child, task.begin, mid, task.depth + 1});
  }

  centroids = {};
  result.nodes.assign(nodes.begin(), nodes.end());
  const uint64_t copy_bytes = order.capacity() * sizeof(uint32_t) + nodes.capacity() * sizeof(BvhNode) +
                              result.nodes.capacity() * sizeof(BvhNode) + kScratchBytes;
  result.peak_bytes = std::max(build_bytes, copy_bytes);
  return result;
}

}  // namespace outcore
