// triangle_may_touch_box: whether a triangle may touch an axis-aligned box,
// by the separating-axis test of Akenine-Möller ("Fast 3D triangle-box
// overlap testing", 2001: the box's three axes, the triangle's normal and
// the nine edge-by-axis cross products), in float64 on a box grown by
// `margin` on every side. Conservative: false only when an axis separates
// the triangle from the grown box by more than float64 rounding could blur,
// so a structure that files a triangle under every box this accepts never
// loses a triangle from a cell it touches (the grid's cells, the octree's).
//
// Thread-safety: a pure function.
#pragma once

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/geometry/vec3.h"

namespace outcore {

// Box [lo, hi] (float64), grown by margin >= 0 on every side.
bool triangle_may_touch_box(const Triangle& triangle, const Vec3d& lo, const Vec3d& hi, double margin);

// The same test against many boxes the triangle's bounds overlap (a
// structure's cells within the span of its bounds): the ten axes that are
// the triangle's own (its normal and the nine edge-by-axis products) and
// the triangle's extent along each are computed once, so a box costs ten
// dot products. The box's own three axes are left out: bounds that overlap
// the box cannot be separated from it along them. Conservative as
// triangle_may_touch_box (the slack covers the rounding of projections
// taken from the origin rather than the box's centre).
namespace overlap_detail {

// A box [lo, hi] grown by margin, as its centre and half extent.
struct GrownBox {
  GrownBox(const Vec3d& lo, const Vec3d& hi, double margin)
      : center((lo + hi) * 0.5), h((hi - lo) * 0.5 + Vec3d(margin, margin, margin)) {}
  Vec3d center, h;
};

// One candidate separating axis and the triangle's extent along it.
struct ProjectedAxis {
  ProjectedAxis() = default;
  ProjectedAxis(const Vec3d& axis, const Vec3d& a, const Vec3d& b, const Vec3d& c);
  // Whether the axis separates the triangle from the box beyond rounding.
  bool separates(const GrownBox& box) const;

  Vec3d axis;
  double min = 0, max = 0, magnitude = 0;
};

}  // namespace overlap_detail

class TriangleBoxOverlap {
 public:
  explicit TriangleBoxOverlap(const Triangle& triangle);
  // `lo`..`hi` must overlap the triangle's bounds (closed).
  bool may_touch_overlapping_box(const Vec3d& lo, const Vec3d& hi, double margin) const;
  // Whether the triangle's plane may touch the box: the first of the ten
  // axes only, a superset of may_touch_overlapping_box() at a tenth of the
  // cost (TrianglePlaneOverlap, which the grids file by, computes only it).
  bool plane_may_touch_box(const Vec3d& lo, const Vec3d& hi, double margin) const;
  // Whether the triangle may touch the column [lo, hi] unbounded along
  // `axis` (the quadtree's cells): exact for a column, whose only
  // separating axes besides its own are the products of the triangle's
  // edges with `axis` (three of the ten). `lo`..`hi` must overlap the
  // triangle's bounds across `axis`.
  bool may_touch_overlapping_column(const Vec3d& lo, const Vec3d& hi, double margin, int axis) const;

 private:
  static constexpr int kAxes = 10;
  overlap_detail::ProjectedAxis axes_[kAxes];  // the normal, then edge e x unit axis a at 1 + 3 e + a
};

// TriangleBoxOverlap::plane_may_touch_box alone, the same answers: only the
// normal is computed (the grids file by it, docs/BENCHMARKS.md, "Grids";
// the nine edge axes were a tenth of a grid's build).
class TrianglePlaneOverlap {
 public:
  explicit TrianglePlaneOverlap(const Triangle& triangle);
  bool plane_may_touch_box(const Vec3d& lo, const Vec3d& hi, double margin) const {
    return !normal_.separates(overlap_detail::GrownBox(lo, hi, margin));
  }

 private:
  overlap_detail::ProjectedAxis normal_;
};

// The margin a structure grows its cells by when it files triangles into
// cells of `cell_size` within `region` (the grid's, an octree node's
// children): 2^-20 of the cell size plus the coordinates' magnitude, far
// above float64 rounding and far below a cell, so the test stays
// conservative without filing triangles into distant cells.
double cell_filing_margin(const Aabb& region, const Vec3d& cell_size);

}  // namespace outcore
