#include "core/accel/bvh/binned_sah_builder.h"

#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>

#include "core/accel/bvh/binned_sah_split.h"

namespace outcore {
namespace {

using binned_sah::BinnedSplit;
using binned_sah::BinScale;
using binned_sah::Box4;
using binned_sah::kMaxBins;

// Below this depth every split is an object median (see the header).
constexpr uint32_t kMedianDepth = kMaxBvhDepth - 33;
// The wide collapse (wide_bvh_collapse.h) turns any subtree of at most one
// packet (8 triangles) into a single leaf, so splitting such a node is work
// the traced tree never sees: most nodes of a binary tree are that small.
constexpr uint32_t kLeafWithoutSplit = 8;

// A triangle as the build moves it: its box and centroid as SSE rows, its
// index in hi[3]. The partitions move these in place, so every pass over a
// node reads one contiguous run instead of gathering boxes and centroids
// through an index array (what made the build memory-bound).
struct alignas(16) PrimRef {
  float lo[4];        // x, y, z, 0
  float hi[4];        // x, y, z, index (its bits)
  float centroid[4];  // x, y, z, 0

  uint32_t index() const { return std::bit_cast<uint32_t>(hi[3]); }
};
static_assert(sizeof(PrimRef) == 48);

// The two halves' boxes and centroid boxes of a split node: for a binned
// split the boxes come from the bins and the centroid boxes from the
// partition; for a median split both from a pass over each half (add).
struct HalfBounds {
  Box4 bounds[2], centroids[2];

  void add(int half, const PrimRef& p) {
    const __m128 c = _mm_load_ps(p.centroid);
    bounds[half].extend(_mm_load_ps(p.lo), _mm_load_ps(p.hi));
    centroids[half].extend(c, c);
  }
};

struct Task {
  uint32_t node, begin, end, depth;
  Box4 bounds, centroids;
};

// The walk is depth first, so at most one pending sibling a level is stacked.
constexpr std::size_t kMaxPendingTasks = 2 * kMaxBvhDepth;
constexpr uint64_t kScratchBytes = 3 * kMaxBins * (sizeof(Box4) + sizeof(uint32_t)) +
                                   kMaxBins * sizeof(double) + kMaxPendingTasks * sizeof(Task) + 4096;

// One build's working state: the triangles' references being partitioned,
// the nodes, and the bins reused by every node.
class SahBuild {
 public:
  SahBuild(std::span<const Triangle> triangles, const BinnedSahBuilder::Config& config)
      : triangles_(triangles), config_(config), bins_(config.bin_count) {}

  // Builds the tree; returns the bytes held while building.
  uint64_t run();
  std::vector<BvhNode>& nodes() { return nodes_; }
  // The triangles' order (position j holds triangle order[j]); frees the references.
  void take_order(std::vector<uint32_t>& order);

 private:
  // Builds `task`'s node: a leaf, or two children pushed on the stack.
  void build_node(const Task& task);
  BinnedSplit best_binned_split(const Task& task, const Aabb& bounds, const BinScale& scale);
  // The end of the left half of `task` after splitting it; halves gets the
  // two halves' boxes.
  uint32_t partition(const Task& task, const BinnedSplit& split, const Aabb& centroid_bounds,
                     HalfBounds& halves);

  std::span<const Triangle> triangles_;
  const BinnedSahBuilder::Config& config_;
  const uint32_t bins_;
  std::vector<PrimRef> prims_;
  // Position j's bin on each axis (a byte each, x lowest) from the last
  // binning of the node holding j.
  std::vector<uint32_t> bins_of_prim_;
  std::vector<BvhNode> nodes_;
  std::vector<Box4> bin_boxes_;
  std::vector<uint32_t> bin_counts_;
  std::vector<double> right_cost_;  // area * count of bins >= b on one axis
  std::vector<Task> stack_;
};

uint64_t SahBuild::run() {
  const uint32_t n = static_cast<uint32_t>(triangles_.size());
  prims_.resize(n);
  bins_of_prim_.resize(n);
  Task root{0, 0, n, 1, {}, {}};
  for (uint32_t k = 0; k < n; ++k) {
    const Aabb b = triangles_[k].bounds();
    const Vec3f c = triangles_[k].centroid();
    PrimRef& p = prims_[k];
    p = {{b.lo.x, b.lo.y, b.lo.z, 0.0f},
         {b.hi.x, b.hi.y, b.hi.z, std::bit_cast<float>(k)},
         {c.x, c.y, c.z, 0.0f}};
    const __m128 centroid = _mm_load_ps(p.centroid);
    root.bounds.extend(_mm_load_ps(p.lo), _mm_load_ps(p.hi));
    root.centroids.extend(centroid, centroid);
  }
  nodes_.reserve(2 * uint64_t{n} - 1);
  nodes_.emplace_back();
  const uint64_t build_bytes = prims_.capacity() * sizeof(PrimRef) +
                               bins_of_prim_.capacity() * sizeof(uint32_t) +
                               nodes_.capacity() * sizeof(BvhNode) + kScratchBytes;
  bin_boxes_.resize(3 * bins_);
  bin_counts_.resize(3 * bins_);
  right_cost_.resize(bins_);
  stack_.reserve(kMaxPendingTasks);
  stack_.push_back(root);
  while (!stack_.empty()) {
    const Task task = stack_.back();
    stack_.pop_back();
    build_node(task);
  }
  return build_bytes;
}

void SahBuild::take_order(std::vector<uint32_t>& order) {
  order.resize(prims_.size());
  for (std::size_t j = 0; j < prims_.size(); ++j) order[j] = prims_[j].index();
  prims_ = {};
  bins_of_prim_ = {};
}

void SahBuild::build_node(const Task& task) {
  const uint32_t count = task.end - task.begin;
  const Aabb bounds = task.bounds.aabb();
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
  const Aabb centroid_bounds = task.centroids.aabb();
  const BinScale scale(centroid_bounds, bins_);
  const BinnedSplit best = task.depth < kMedianDepth ? best_binned_split(task, bounds, scale) : BinnedSplit{};
  const double leaf_cost = double{config_.intersection_cost} * count;
  if (count <= config_.max_leaf_size && (best.axis < 0 || leaf_cost <= best.cost)) {
    node.index = task.begin;
    node.count = count;
    return;
  }
  HalfBounds halves;
  const uint32_t mid = partition(task, best, centroid_bounds, halves);
  assert(mid > task.begin && mid < task.end);
  const uint32_t child = static_cast<uint32_t>(nodes_.size());
  node.index = child;
  node.count = 0;
  nodes_.emplace_back();  // no reallocation: reserved for a full tree
  nodes_.emplace_back();
  stack_.push_back({child + 1, mid, task.end, task.depth + 1, halves.bounds[1], halves.centroids[1]});
  stack_.push_back({child, task.begin, mid, task.depth + 1, halves.bounds[0], halves.centroids[0]});
}

BinnedSplit SahBuild::best_binned_split(const Task& task, const Aabb& bounds, const BinScale& scale) {
  std::fill(bin_boxes_.begin(), bin_boxes_.end(), Box4{});
  std::fill(bin_counts_.begin(), bin_counts_.end(), 0u);
  // All three axes' bins at once: lane a is BinScale::bin_of(c, a)'s IEEE
  // operations (an unusable axis's lane is clamped into range and ignored).
  const __m128 lo = _mm_setr_ps(scale.lo[0], scale.lo[1], scale.lo[2], 0.0f);
  const __m128 factor = _mm_setr_ps(scale.scale[0], scale.scale[1], scale.scale[2], 0.0f);
  const __m128 zero = _mm_setzero_ps(), last = _mm_set1_ps(static_cast<float>(bins_ - 1));
  const __m128i offsets = _mm_setr_epi32(0, static_cast<int>(bins_), static_cast<int>(2 * bins_), 0);
  Box4* boxes = bin_boxes_.data();
  uint32_t* counts = bin_counts_.data();
  for (uint32_t j = task.begin; j < task.end; ++j) {
    const PrimRef& p = prims_[j];
    // max(x, 0) returns 0 for a NaN x, as std::max(0.0f, x) does.
    const __m128 x =
        _mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(p.centroid), lo), factor), zero), last);
    const __m128i own = _mm_cvttps_epi32(x);
    // Kept for the partition, which then needs no bin_of of its own.
    bins_of_prim_[j] =
        static_cast<uint32_t>(_mm_cvtsi128_si32(_mm_packus_epi16(_mm_packus_epi32(own, own), own)));
    alignas(16) int32_t bin[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(bin), _mm_add_epi32(own, offsets));
    const __m128 box_lo = _mm_load_ps(p.lo), box_hi = _mm_load_ps(p.hi);
    for (int a = 0; a < 3; ++a) {
      boxes[bin[a]].extend(box_lo, box_hi);
      ++counts[bin[a]];
    }
  }
  return binned_sah::cheapest_split(boxes, counts, scale, task.end - task.begin, bounds, config_,
                                    right_cost_.data());
}

uint32_t SahBuild::partition(const Task& task, const BinnedSplit& split, const Aabb& centroid_bounds,
                             HalfBounds& halves) {
  if (split.axis >= 0) {
    // The bins the split was chosen from give each half's box exactly (the
    // same min and max of the same triangles' boxes); the centroid boxes are
    // gathered while partitioning.
    const Box4* boxes = bin_boxes_.data() + split.axis * bins_;
    for (uint32_t b = 0; b < bins_; ++b) halves.bounds[b < split.bin ? 0 : 1].extend(boxes[b]);
    const int shift = 8 * split.axis;
    const auto goes_left = [&](uint32_t j) { return (bins_of_prim_[j] >> shift & 0xffu) < split.bin; };
    const auto add_centroid = [&](int half, const PrimRef& p) {
      const __m128 c = _mm_load_ps(p.centroid);
      halves.centroids[half].extend(c, c);
    };
    uint32_t i = task.begin, j = task.end;
    while (true) {
      while (i < j && goes_left(i)) add_centroid(0, prims_[i++]);
      while (i < j && !goes_left(j - 1)) add_centroid(1, prims_[--j]);
      if (i == j) return i;
      // prims_[i] goes right and prims_[j - 1] left: swapped, both are placed.
      std::swap(prims_[i], prims_[j - 1]);
      add_centroid(0, prims_[i++]);
      add_centroid(1, prims_[--j]);
    }
  }
  // Object median along the widest centroid spread (index order when the
  // centroids coincide): always two non-empty halves.
  const int axis = centroid_bounds.largest_axis();
  const uint32_t mid = task.begin + (task.end - task.begin) / 2;
  std::nth_element(prims_.begin() + task.begin, prims_.begin() + mid, prims_.begin() + task.end,
                   [&](const PrimRef& x, const PrimRef& y) {
                     const float cx = x.centroid[axis], cy = y.centroid[axis];
                     return cx < cy || (cx == cy && x.index() < y.index());
                   });
  for (uint32_t j = task.begin; j < task.end; ++j) halves.add(j < mid ? 0 : 1, prims_[j]);
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
  // The references and their bins + nodes reserved for a full binary tree
  // (2n - 1), then the order beside them, then order + that + the exact copy (again at most
  // 2n - 1 nodes).
  return kScratchBytes + n * (sizeof(PrimRef) + 2 * sizeof(uint32_t)) + 4 * n * sizeof(BvhNode);
}

BinnedSahBuilder::Result BinnedSahBuilder::build(std::span<const Triangle> triangles, const Config& config) {
  assert(config.validate().ok());
  Result result;
  if (triangles.empty()) return result;
  SahBuild build(triangles, config);
  const uint64_t build_bytes = build.run() + triangles.size() * sizeof(uint32_t);
  build.take_order(result.order);
  const std::vector<BvhNode>& nodes = build.nodes();
  result.nodes.assign(nodes.begin(), nodes.end());
  const uint64_t copy_bytes = result.order.capacity() * sizeof(uint32_t) +
                              nodes.capacity() * sizeof(BvhNode) + result.nodes.capacity() * sizeof(BvhNode) +
                              kScratchBytes;
  result.peak_bytes = std::max(build_bytes, copy_bytes);
  return result;
}

}  // namespace outcore
