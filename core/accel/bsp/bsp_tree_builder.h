// BspTreeBuilder: an SAH restricted BSP tree over a brick's triangles, with
// planes along the first `directions` (3, 7 or 13) orientations of
// bsp_directions.h (Kammaje & Mora 2007; Budge et al. 2008).
//
// Each node is a cell: a k-DOP (an interval along each of the 13 directions;
// the root's is that of all triangles) and the same cell as a polytope
// (bsp_polytope.h) for its surface area. A reference carries its triangle's
// extents along all 13 directions within the cell. Candidate planes per
// direction: for a node of at most kExactCandidates references, every
// reference's extent ends (exact SAH); above that, kBins - 1 evenly spaced
// planes over the cell's extent (binned SAH, counts from the references'
// bins). A child's surface area as a function of the plane's position is the
// quadratic through the exact areas at the cell's ends and middle: exact for
// the axes on a box, an approximation otherwise, and three polytope passes
// per direction instead of one per candidate.
//
// Cost model as the kd-tree's (kd_tree_builder.h): traversal_cost +
// intersection_cost * (A_below N_below + A_above N_above) / A, times
// (1 - empty_bonus) when a side is empty; a leaf when nothing is cheaper than
// intersection_cost * N, at the depth limit, or past the reference or node
// budget (kMaxReferencesPerTriangle references a triangle on average), which
// bounds memory for the cache's reservation.
//
// Conservative: a triangle straddling the chosen plane goes to both children
// (its part in the parent cell spans the plane, so it reaches both); its
// extents in a child are those of the triangle clipped in float64 by every
// cell plane it crosses, widened by 2^-40 |p|_1 (far beyond float64's
// rounding of the clip and of n . p) and rounded outward to float, then
// clamped to the cell. A triangle is never dropped from a cell it touches.
//
// Thread-safety: build() is reentrant (no shared state).
#pragma once

#include <cstdint>
#include <vector>

#include "core/accel/bsp/bsp_tree.h"
#include "core/accel/kdtree/split_tree_costs.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

class BspTreeBuilder {
 public:
  // The kd-tree's (pbrt-v3's) constants and depth limit, and the directions.
  struct Config : SplitTreeCosts {
    // 3 (the kd-tree's axes), 7 (and the cube diagonals) or 13 (and the face
    // diagonals).
    uint32_t directions = 13;

    Status validate() const;
  };

  static constexpr uint64_t kMaxReferencesPerTriangle = 4;
  // Triangles a build takes: node indices and reference counts must fit 28
  // bits (kMaxBspIndex) under the budgets (16 nodes a triangle at most).
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 23;
  static constexpr uint32_t kBins = 16;
  static constexpr uint32_t kExactCandidates = 24;

  struct Result {
    BspTree tree;
    uint64_t peak_bytes = 0;  // the build's own scratch at its largest (references)
  };

  // triangles: usable ones (finite, not degenerate); ids[k] belongs to
  // triangles[k]. The tree keeps them in this order.
  static Result build(std::vector<Triangle> triangles, const std::vector<TriangleId>& ids,
                      const Config& config);

  // Upper bounds, for n triangles: the tree's arrays, and the build's peak
  // scratch.
  static uint64_t tree_bytes_bound(uint64_t n);
  static uint64_t peak_bytes_bound(uint64_t n);
  static uint32_t depth_limit(const Config& config, uint64_t n);
};

}  // namespace outcore
