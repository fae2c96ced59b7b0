// KdTreeBuilder: an SAH kd-tree over a brick's triangles in O(N log N), the
// event sweep of Wald & Havran 2006 ("On building fast kd-trees for ray
// tracing, and on doing that in O(N log N)"): the candidate planes of every
// axis are sorted once at the root; each node sweeps its sorted events to find
// the cheapest split, and hands its children their events still sorted
// (triangles on one side keep theirs; only the triangles that straddle the
// plane are clipped to each child's box — perfect splits — and their new
// events sorted and merged in).
//
// Cost model: traversal_cost + intersection_cost * (P_below * N_below +
// P_above * N_above), P the children's surface area over the node's, scaled by
// (1 - empty_bonus) when a child is empty; a node becomes a leaf when no split
// costs less than intersecting all its triangles, at the depth limit, or when
// the tree would exceed its reference or node budget (kMaxReferencesPerTriangle
// references a triangle on average), which bounds memory for the cache's
// reservation.
//
// Clipping is conservative: a triangle's clipped bounds are computed in
// float64 and rounded outward, so a triangle is never left out of a cell it
// touches.
//
// Thread-safety: build() is reentrant (no shared state).
#pragma once

#include <cstdint>
#include <vector>

#include "core/accel/kdtree/kd_tree.h"
#include "core/accel/kdtree/split_tree_costs.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

class KdTreeBuilder {
 public:
  struct Config : SplitTreeCosts {
    Status validate() const { return SplitTreeCosts::validate("kdtree", kMaxKdDepth); }
  };

  static constexpr uint64_t kMaxReferencesPerTriangle = 4;
  // Triangles a build takes: an event keeps its triangle in 24 bits, and
  // node indices and reference counts must fit 30 bits (kMaxKdIndex) under
  // the budgets (16 nodes a triangle at most).
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 24;

  struct Result {
    KdTree tree;
    uint64_t peak_bytes = 0;  // the build's own scratch at its largest (events, flags)
  };

  // triangles: usable ones (finite, not degenerate); ids[k] belongs to
  // triangles[k]. The tree keeps them in this order.
  static Result build(std::vector<Triangle> triangles, const std::vector<TriangleId>& ids,
                      const Config& config);

  // Upper bounds, for n triangles: the tree's arrays, and the build's peak
  // scratch (events and flags).
  static uint64_t tree_bytes_bound(uint64_t n);
  static uint64_t peak_bytes_bound(uint64_t n);
  // The depth limit build() uses for n triangles.
  static uint32_t depth_limit(const Config& config, uint64_t n);
};

}  // namespace outcore
