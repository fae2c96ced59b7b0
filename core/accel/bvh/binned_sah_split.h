// The binned SAH's decisions, shared by BinnedSahBuilder and the simple
// reference build its test compares it with: which bin a centroid falls in,
// and which bin boundary is the cheapest split once a node's triangles are
// binned. Keeping them in one place is what lets the fast builder (SIMD
// binning, triangles moved in place) be checked to make exactly the
// reference's tree. Boxes are SSE rows (Box4); their half areas are
// Aabb::half_area's double operations.
//
// Thread-safety: plain values and pure functions.
#pragma once

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/accel/bvh/binned_sah_builder.h"
#include "core/geometry/aabb.h"

namespace outcore::binned_sah {

inline constexpr uint32_t kMaxBins = 256;

// A box as two SSE rows (x, y, z in lanes 0..2); lane 3 carries nothing.
struct Box4 {
  __m128 lo = _mm_set1_ps(std::numeric_limits<float>::infinity());
  __m128 hi = _mm_set1_ps(-std::numeric_limits<float>::infinity());

  static Box4 of(const Aabb& b) {
    return {_mm_setr_ps(b.lo.x, b.lo.y, b.lo.z, 0.0f), _mm_setr_ps(b.hi.x, b.hi.y, b.hi.z, 0.0f)};
  }
  void extend(__m128 l, __m128 h) {
    lo = _mm_min_ps(lo, l);
    hi = _mm_max_ps(hi, h);
  }
  void extend(const Box4& b) { extend(b.lo, b.hi); }
  Aabb aabb() const {
    alignas(16) float l[4], h[4];
    _mm_store_ps(l, lo);
    _mm_store_ps(h, hi);
    return {{l[0], l[1], l[2]}, {h[0], h[1], h[2]}};
  }
  // Aabb::half_area, bit for bit: 0 when empty, else the float extents'
  // pairwise products summed in double.
  double half_area() const {
    if ((_mm_movemask_ps(_mm_cmpgt_ps(lo, hi)) & 7) != 0) return 0.0;
    alignas(16) float e[4];
    _mm_store_ps(e, _mm_sub_ps(hi, lo));
    const double x = e[0], y = e[1], z = e[2];
    return x * y + y * z + z * x;
  }
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
  // fl(fl(c - lo) * scale) clamped to the bins; a NaN lands in bin 0. The
  // SIMD binning computes the same IEEE operations lane by lane.
  uint32_t bin_of(float c, int a) const {
    const float x = (c - lo[a]) * scale[a];
    return std::min(bins - 1, static_cast<uint32_t>(std::max(0.0f, x)));
  }
};

// The cheapest boundary over the usable axes of a node of `count` triangles
// with box `bounds`, from its bins: bin_bounds and bin_counts hold 3 * bins
// entries, axis by axis. right_cost is scratch for `bins` doubles. No split
// (axis -1) when no boundary separates the triangles; of equal costs the
// first (axis, then boundary) wins. A boundary just above an empty bin
// splits as the one below it, at the same cost to the bit, so it is not
// evaluated again: most bins of small nodes are empty.
inline BinnedSplit cheapest_split(const Box4* bin_bounds, const uint32_t* bin_counts, const BinScale& scale,
                                  uint32_t count, const Aabb& bounds, const BinnedSahBuilder::Config& config,
                                  double* right_cost) {
  const uint32_t bins = scale.bins;
  BinnedSplit best;
  const double inv_area = bounds.half_area() > 0.0 ? 1.0 / bounds.half_area() : 0.0;
  for (int a = 0; a < 3; ++a) {
    if (!scale.usable[a]) continue;
    const Box4* ab = bin_bounds + a * bins;
    const uint32_t* ac = bin_counts + a * bins;
    Box4 right;
    uint32_t right_count = 0;
    for (uint32_t b = bins - 1; b > 0; --b) {
      if (ac[b] == 0 && b + 1 < bins) {
        right_cost[b] = right_cost[b + 1];
        continue;
      }
      right.extend(ab[b]);
      right_count += ac[b];
      right_cost[b] = right.half_area() * right_count;
    }
    Box4 left;
    uint32_t left_count = 0;
    for (uint32_t b = 1; b < bins; ++b) {
      if (ac[b - 1] == 0) continue;
      left.extend(ab[b - 1]);
      left_count += ac[b - 1];
      if (left_count == count) break;
      const double cost = config.traversal_cost + config.intersection_cost * inv_area *
                                                      (left.half_area() * left_count + right_cost[b]);
      if (cost < best.cost) best = {a, b, cost};
    }
  }
  return best;
}

}  // namespace outcore::binned_sah
