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
// The wide collapse (wide_bvh_collapse.h) turns any subtree of at most one
// packet (8 triangles) into a single leaf, so splitting such a node is work
// the traced tree never sees: most nodes of a binary tree are that small.
constexpr uint32_t kLeafWithoutSplit = 8;
constexpr uint64_t kScratchBytes = 3 * kMaxBins * (sizeof(Aabb) + sizeof(uint32_t)) + kMaxBins * 16 + 4096;

struct Task {
  uint32_t node, begin, end, depth;
};

struct BinnedSplit {
  int axis = -1;
  uint32_t bin = 0;  // triangles in bins < bin go left
  double cost = std::numeric_limits<double>::infinity();
};

// Per-axis bin scale of one node's centroid bounds; an axis whose centroids
// do not spread (or whose spread is too small to scale) offers no split.
struct BinScale {
  float lo[3], scale[3];
  bool usable[3];
  uint32_t bins;

  BinScale(const Aabb& centroid_bounds, uint32_t bin_count) : bins(bin_count) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = centroid_bounds.lo[a];
      const float extent = centroid_bounds.hi[a] - centroid_bounds.lo[a];
      scale[a] = extent > 0.0f ? static_cast<float>(bins) / extent : 0.0f;
      usable[a] = extent > 0.0f && std::isfinite(scale[a]);
    }
  }
  uint32_t bin_of(const Vec3f& c, int a) const {
    const float x = (c[a] - lo[a]) * scale[a];
    return std::min(bins - 1, static_cast<uint32_t>(std::max(0.0f, x)));
  }
};

// One build's working state: the centroids, the order being partitioned, the
// nodes, and the bins reused by every node.
class SahBuild {
 public:
  SahBuild(std::span<const Triangle> triangles, const BinnedSahBuilder::Config& config,
           std::vector<uint32_t>& order)
      : triangles_(triangles), config_(config), bins_(config.bin_count), order_(order) {}

  // Builds the tree; returns the bytes held while building.
  uint64_t run();
  std::vector<BvhNode>& nodes() { return nodes_; }
  void release_centroids() {
    centroids_ = {};
    bounds_ = {};
  }

 private:
  // Builds `task`'s node: a leaf, or two children pushed on the stack.
  void build_node(const Task& task);
  BinnedSplit best_binned_split(const Task& task, const Aabb& bounds, const BinScale& scale);
  // The end of the left half of `task` after splitting it.
  uint32_t partition(const Task& task, const BinnedSplit& split, const Aabb& centroid_bounds,
                     const BinScale& scale);

  std::span<const Triangle> triangles_;
  const BinnedSahBuilder::Config& config_;
  const uint32_t bins_;
  std::vector<uint32_t>& order_;
  std::vector<Vec3f> centroids_;
  std::vector<Aabb> bounds_;  // each triangle's, computed once
  std::vector<BvhNode> nodes_;
  std::vector<Aabb> bin_bounds_;
  std::vector<uint32_t> bin_counts_;
  std::vector<double> right_cost_;  // area * count of bins >= b on one axis
  std::vector<Task> stack_;
};

uint64_t SahBuild::run() {
  const uint32_t n = static_cast<uint32_t>(triangles_.size());
  centroids_.resize(n);
  bounds_.resize(n);
  for (uint32_t k = 0; k < n; ++k) {
    centroids_[k] = triangles_[k].centroid();
    bounds_[k] = triangles_[k].bounds();
  }
  order_.resize(n);
  for (uint32_t k = 0; k < n; ++k) order_[k] = k;
  nodes_.reserve(2 * uint64_t{n} - 1);
  nodes_.emplace_back();
  const uint64_t build_bytes = centroids_.capacity() * sizeof(Vec3f) + bounds_.capacity() * sizeof(Aabb) +
                               order_.capacity() * sizeof(uint32_t) + nodes_.capacity() * sizeof(BvhNode) +
                               kScratchBytes;
  bin_bounds_.resize(3 * bins_);
  bin_counts_.resize(3 * bins_);
  right_cost_.resize(bins_);
  stack_.push_back({0, 0, n, 1});
  while (!stack_.empty()) {
    const Task task = stack_.back();
    stack_.pop_back();
    build_node(task);
  }
  return build_bytes;
}

void SahBuild::build_node(const Task& task) {
  const uint32_t count = task.end - task.begin;
  Aabb bounds, centroid_bounds;
  for (uint32_t j = task.begin; j < task.end; ++j) {
    bounds.extend(bounds_[order_[j]]);
    centroid_bounds.extend(centroids_[order_[j]]);
  }
  BvhNode& node = nodes_[task.node];
  node.bounds = bounds;
  if (count == 1) {
    node.index = task.begin;
    node.count = 1;
    return;
  }
  if (count <= config_.max_leaf_size && count <= kLeafWithoutSplit) {
    node.index = task.begin;
    node.count = count;
    return;
  }
  const BinScale scale(centroid_bounds, bins_);
  const BinnedSplit best = task.depth < kMedianDepth ? best_binned_split(task, bounds, scale) : BinnedSplit{};
  const double leaf_cost = double{config_.intersection_cost} * count;
  if (count <= config_.max_leaf_size && (best.axis < 0 || leaf_cost <= best.cost)) {
    node.index = task.begin;
    node.count = count;
    return;
  }
  const uint32_t mid = partition(task, best, centroid_bounds, scale);
  assert(mid > task.begin && mid < task.end);
  const uint32_t child = static_cast<uint32_t>(nodes_.size());
  node.index = child;
  node.count = 0;
  nodes_.emplace_back();  // no reallocation: reserved for a full tree
  nodes_.emplace_back();
  stack_.push_back({child + 1, mid, task.end, task.depth + 1});
  stack_.push_back({child, task.begin, mid, task.depth + 1});
}

BinnedSplit SahBuild::best_binned_split(const Task& task, const Aabb& bounds, const BinScale& scale) {
  const uint32_t count = task.end - task.begin;
  std::fill(bin_bounds_.begin(), bin_bounds_.end(), Aabb{});
  std::fill(bin_counts_.begin(), bin_counts_.end(), 0u);
  for (uint32_t j = task.begin; j < task.end; ++j) {
    const Aabb& b = bounds_[order_[j]];
    const Vec3f& c = centroids_[order_[j]];
    for (int a = 0; a < 3; ++a) {
      if (!scale.usable[a]) continue;
      const uint32_t bin = a * bins_ + scale.bin_of(c, a);
      bin_bounds_[bin].extend(b);
      ++bin_counts_[bin];
    }
  }
  BinnedSplit best;
  const double inv_area = bounds.half_area() > 0.0 ? 1.0 / bounds.half_area() : 0.0;
  for (int a = 0; a < 3; ++a) {
    if (!scale.usable[a]) continue;
    const Aabb* ab = &bin_bounds_[a * bins_];
    const uint32_t* ac = &bin_counts_[a * bins_];
    Aabb right;
    uint32_t right_count = 0;
    for (uint32_t b = bins_ - 1; b > 0; --b) {
      right.extend(ab[b]);
      right_count += ac[b];
      right_cost_[b] = right.half_area() * right_count;
    }
    Aabb left;
    uint32_t left_count = 0;
    for (uint32_t b = 1; b < bins_; ++b) {
      left.extend(ab[b - 1]);
      left_count += ac[b - 1];
      if (left_count == 0 || left_count == count) continue;
      const double cost = config_.traversal_cost + config_.intersection_cost * inv_area *
                                                       (left.half_area() * left_count + right_cost_[b]);
      if (cost < best.cost) best = {a, b, cost};
    }
  }
  return best;
}

uint32_t SahBuild::partition(const Task& task, const BinnedSplit& split, const Aabb& centroid_bounds,
                             const BinScale& scale) {
  if (split.axis >= 0) {
    const auto first = order_.begin() + task.begin, last = order_.begin() + task.end;
    return static_cast<uint32_t>(
        std::partition(first, last,
                       [&](uint32_t k) { return scale.bin_of(centroids_[k], split.axis) < split.bin; }) -
        order_.begin());
  }
  // Object median along the widest centroid spread (index order when the
  // centroids coincide): always two non-empty halves.
  const int axis = centroid_bounds.largest_axis();
  const uint32_t mid = task.begin + (task.end - task.begin) / 2;
  std::nth_element(order_.begin() + task.begin, order_.begin() + mid, order_.begin() + task.end,
                   [&](uint32_t x, uint32_t y) {
                     const float cx = centroids_[x][axis], cy = centroids_[y][axis];
                     return cx < cy || (cx == cy && x < y);
                   });
  return mid;
}

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
  // centroids, bounds + order + nodes reserved for a full binary tree (2n - 1), then
  // order + that + the exact copy (again at most 2n - 1 nodes).
  return kScratchBytes + n * (sizeof(Vec3f) + sizeof(Aabb) + sizeof(uint32_t)) + 4 * n * sizeof(BvhNode);
}

BinnedSahBuilder::Result BinnedSahBuilder::build(std::span<const Triangle> triangles, const Config& config) {
  assert(config.validate().ok());
  Result result;
  if (triangles.empty()) return result;
  SahBuild build(triangles, config, result.order);
  const uint64_t build_bytes = build.run();
  build.release_centroids();
  const std::vector<BvhNode>& nodes = build.nodes();
  result.nodes.assign(nodes.begin(), nodes.end());
  const uint64_t copy_bytes = result.order.capacity() * sizeof(uint32_t) +
                              nodes.capacity() * sizeof(BvhNode) + result.nodes.capacity() * sizeof(BvhNode) +
                              kScratchBytes;
  result.peak_bytes = std::max(build_bytes, copy_bytes);
  return result;
}

}  // namespace outcore
