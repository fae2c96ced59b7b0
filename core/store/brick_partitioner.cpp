#include "core/store/brick_partitioner.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <limits>

namespace outcore {

namespace {

constexpr int kMaxBins = 64;
// Below this many triangles a node is binned serially and its children are not
// spawned as tasks: the task overhead would exceed the work.
constexpr std::size_t kParallelThreshold = 1 << 16;
// Nodes larger than this choose their split from a strided sample of about
// kSampleSize triangles: the SAH estimate barely changes, and the top levels
// then cost one partition pass instead of a binning pass too. Stats derived
// from a sample are only used to place bins; brick bounds are always exact.
constexpr std::size_t kSampleThreshold = 1 << 16;
constexpr std::size_t kSampleSize = 1 << 13;

// What a node knows about its triangles; children get theirs from the parent's
// bins, so every level costs one binning pass and one partition pass.
struct NodeStats {
  Aabb bounds;
  Aabb centroid_bounds;
  bool exact = true;  // false when estimated from a sample
  void extend(const NodeStats& o) {
    bounds.extend(o.bounds);
    centroid_bounds.extend(o.centroid_bounds);
  }
};

struct Bin {
  NodeStats stats;
  uint64_t count = 0;
};

using Bins = std::array<Bin, kMaxBins>;

class Partitioner {
 public:
  Partitioner(std::span<PackedTriangle> triangles, const BrickPartitionerConfig& config)
      : triangles_(triangles),
        max_triangles_(std::max<uint32_t>(1, config.max_triangles)),
        bins_(std::clamp(config.bins, 2, kMaxBins)),
        overhead_(config.brick_overhead_triangles > 0 ? config.brick_overhead_triangles
                                                      : 0.5 * std::max<uint32_t>(1, config.max_triangles)) {}

  std::vector<BrickRange> run() {
    std::vector<BrickRange> out;
    if (triangles_.empty()) return out;
    split(0, triangles_.size(), root_stats(), out);
    return out;
  }

 private:
  template <class Body, class Join, class T>
  T reduce(std::size_t begin, std::size_t end, const T& identity, const Body& body, const Join& join) const {
    if (end - begin < kParallelThreshold) return body(tbb::blocked_range<std::size_t>(begin, end), identity);
    return tbb::parallel_reduce(tbb::blocked_range<std::size_t>(begin, end, 1 << 14), identity, body, join);
  }

  NodeStats root_stats() const {
    return reduce(
        0, triangles_.size(), NodeStats{},
        [&](const tbb::blocked_range<std::size_t>& r, NodeStats acc) {
          for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Triangle& t = triangles_[i].tri;
            acc.bounds.extend(t.bounds());
            acc.centroid_bounds.extend(t.centroid());
          }
          return acc;
        },
        [](NodeStats a, const NodeStats& b) {
          a.extend(b);
          return a;
        });
  }

  // Triangles plus the overhead of the bricks they will need: sides that fill
  // whole bricks are cheaper than sides that leave a brick half empty.
  double side_cost(uint64_t count) const {
    const uint64_t bricks = (count + max_triangles_ - 1) / max_triangles_;
    return static_cast<double>(count) + overhead_ * static_cast<double>(bricks);
  }

  int bin_of(float centroid, float lo, float scale) const {
    const int k = static_cast<int>((centroid - lo) * scale);
    return std::clamp(k, 0, bins_ - 1);
  }

  // Bins along one axis (the centroids' longest): cheaper than binning all
  // three, and brick boundaries need compactness more than optimal planes.
  Bins bin(std::size_t begin, std::size_t end, std::size_t stride, int axis, float lo, float scale) const {
    const std::size_t samples = (end - begin + stride - 1) / stride;
    return reduce(
        0, samples, Bins{},
        [&](const tbb::blocked_range<std::size_t>& r, Bins acc) {
          for (std::size_t i = r.begin(); i < r.end(); ++i) {
            const Triangle& t = triangles_[begin + i * stride].tri;
            const Vec3f c = t.centroid();
            Bin& b = acc[bin_of(c[axis], lo, scale)];
            b.stats.bounds.extend(t.bounds());
            b.stats.centroid_bounds.extend(c);
            ++b.count;
          }
          return acc;
        },
        [&](Bins a, const Bins& b) {
          for (int k = 0; k < bins_; ++k) {
            a[k].stats.extend(b[k].stats);
            a[k].count += b[k].count;
          }
          return a;
        });
  }

  void split(std::size_t begin, std::size_t end, const NodeStats& node, std::vector<BrickRange>& out) {
    const std::size_t count = end - begin;
    if (count <= max_triangles_) {
      out.push_back({begin, count, node.exact ? node.bounds : range_stats(begin, end).bounds});
      return;
    }
    const Aabb& cb = node.centroid_bounds;
    const int axis = cb.largest_axis();
    const float extent = cb.hi[axis] - cb.lo[axis];
    float scale = extent > 0.0f ? static_cast<float>(bins_) / extent : 0.0f;
    if (!std::isfinite(scale)) scale = 0.0f;

    std::size_t middle = begin;
    NodeStats left_stats, right_stats;
    if (scale > 0.0f) {
      const std::size_t stride = count > kSampleThreshold ? count / kSampleSize : 1;
      const Bins bins = bin(begin, end, stride, axis, cb.lo[axis], scale);
      std::array<double, kMaxBins> right_cost{};
      NodeStats right;
      uint64_t right_count = 0;
      for (int k = bins_ - 1; k > 0; --k) {
        right.extend(bins[k].stats);
        right_count += bins[k].count;
        right_cost[k] = right_count ? right.bounds.half_area() * side_cost(right_count) : -1.0;
      }
      double best_cost = std::numeric_limits<double>::infinity();
      int best_bin = -1;
      NodeStats left;
      uint64_t left_count = 0;
      for (int k = 0; k + 1 < bins_; ++k) {
        left.extend(bins[k].stats);
        left_count += bins[k].count;
        if (left_count == 0 || right_cost[k + 1] < 0.0) continue;
        const double cost = left.bounds.half_area() * side_cost(left_count) + right_cost[k + 1];
        if (cost < best_cost) {
          best_cost = cost;
          best_bin = k + 1;  // bins [0, best_bin) go left
        }
      }
      if (best_bin > 0) {
        for (int k = 0; k < bins_; ++k) (k < best_bin ? left_stats : right_stats).extend(bins[k].stats);
        left_stats.exact = right_stats.exact = stride == 1;
        const float lo = cb.lo[axis];
        auto* first = triangles_.data() + begin;
        auto* mid = std::partition(first, triangles_.data() + end, [&](const PackedTriangle& p) {
          return bin_of(p.tri.centroid()[axis], lo, scale) < best_bin;
        });
        middle = begin + static_cast<std::size_t>(mid - first);
      }
    }
    if (middle == begin || middle == end) {
      // Identical centroids (or no valid plane): split in sequence order, which
      // keeps the result deterministic and still bounds brick sizes.
      middle = begin + count / 2;
      left_stats = range_stats(begin, middle);
      right_stats = range_stats(middle, end);
    }

    if (count >= kParallelThreshold) {
      std::vector<BrickRange> left_out, right_out;
      tbb::task_group group;
      group.run([&] { split(begin, middle, left_stats, left_out); });
      split(middle, end, right_stats, right_out);
      group.wait();
      out.insert(out.end(), left_out.begin(), left_out.end());
      out.insert(out.end(), right_out.begin(), right_out.end());
    } else {
      split(begin, middle, left_stats, out);
      split(middle, end, right_stats, out);
    }
  }

  NodeStats range_stats(std::size_t begin, std::size_t end) const {
    NodeStats s;
    for (std::size_t i = begin; i < end; ++i) {
      s.bounds.extend(triangles_[i].tri.bounds());
      s.centroid_bounds.extend(triangles_[i].tri.centroid());
    }
    return s;
  }

  std::span<PackedTriangle> triangles_;
  uint32_t max_triangles_;
  int bins_;
  double overhead_;
};

}  // namespace

std::vector<BrickRange> partition_into_bricks(std::span<PackedTriangle> triangles,
                                              const BrickPartitionerConfig& config) {
  return Partitioner(triangles, config).run();
}

}  // namespace outcore
