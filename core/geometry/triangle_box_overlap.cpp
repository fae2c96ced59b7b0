#include "core/geometry/triangle_box_overlap.h"

#include <algorithm>
#include <cmath>

namespace outcore {
namespace {

// Rounding of the float64 projections below is ~1e-16 of the magnitudes
// involved; this relative slack, far above it, keeps the test conservative.
constexpr double kRelativeSlack = 0x1p-40;

// Whether axis separates the triangle (vertices a, b, c relative to the box
// center) from the box of half extent h.
bool separates(const Vec3d& axis, const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& h) {
  const double pa = dot(axis, a), pb = dot(axis, b), pc = dot(axis, c);
  const double radius = h.x * std::abs(axis.x) + h.y * std::abs(axis.y) + h.z * std::abs(axis.z);
  const double scale = radius + std::max({std::abs(pa), std::abs(pb), std::abs(pc)});
  const double slack = scale * kRelativeSlack;
  return std::min({pa, pb, pc}) > radius + slack || std::max({pa, pb, pc}) < -radius - slack;
}

}  // namespace

double cell_filing_margin(const Aabb& region, const Vec3d& cell_size) {
  double margin = 0;
  for (int a = 0; a < 3; ++a) {
    const double magnitude = std::max(std::abs(double{region.lo[a]}), std::abs(double{region.hi[a]}));
    margin = std::max(margin, 0x1p-20 * (cell_size[a] + magnitude));
  }
  return margin;
}

bool triangle_may_touch_box(const Triangle& triangle, const Vec3d& lo, const Vec3d& hi, double margin) {
  const Vec3d center = (lo + hi) * 0.5;
  const Vec3d h = (hi - lo) * 0.5 + Vec3d(margin, margin, margin);
  const Vec3d a = Vec3d(triangle.v0) - center;
  const Vec3d b = Vec3d(triangle.v1) - center;
  const Vec3d c = Vec3d(triangle.v2) - center;
  const Vec3d unit[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (const Vec3d& axis : unit) {
    if (separates(axis, a, b, c, h)) return false;
  }
  const Vec3d edges[3] = {b - a, c - b, a - c};
  if (separates(cross(edges[0], edges[1]), a, b, c, h)) return false;
  for (const Vec3d& edge : edges) {
    for (const Vec3d& axis : unit) {
      if (separates(cross(edge, axis), a, b, c, h)) return false;
    }
  }
  return true;
}

namespace overlap_detail {

ProjectedAxis::ProjectedAxis(const Vec3d& axis_, const Vec3d& a, const Vec3d& b, const Vec3d& c)
    : axis(axis_) {
  const double pa = dot(axis, a), pb = dot(axis, b), pc = dot(axis, c);
  min = std::min({pa, pb, pc});
  max = std::max({pa, pb, pc});
  magnitude = std::max({std::abs(pa), std::abs(pb), std::abs(pc)});
}

bool ProjectedAxis::separates(const GrownBox& box) const {
  const double at_center = dot(axis, box.center);
  const double radius = box.h.x * std::abs(axis.x) + box.h.y * std::abs(axis.y) + box.h.z * std::abs(axis.z);
  // Projections taken from the origin: the slack scales with every
  // magnitude involved, the centre's and the vertices' included.
  const double slack = (radius + magnitude + std::abs(at_center)) * kRelativeSlack;
  return min - at_center > radius + slack || max - at_center < -radius - slack;
}

}  // namespace overlap_detail

using overlap_detail::GrownBox;
using overlap_detail::ProjectedAxis;

TriangleBoxOverlap::TriangleBoxOverlap(const Triangle& triangle) {
  const Vec3d a(triangle.v0), b(triangle.v1), c(triangle.v2);
  const Vec3d edges[3] = {b - a, c - b, a - c};
  const Vec3d unit[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  axes_[0] = ProjectedAxis(cross(edges[0], edges[1]), a, b, c);
  int k = 1;
  for (const Vec3d& edge : edges) {
    for (const Vec3d& axis : unit) axes_[k++] = ProjectedAxis(cross(edge, axis), a, b, c);
  }
}

bool TriangleBoxOverlap::may_touch_overlapping_box(const Vec3d& lo, const Vec3d& hi, double margin) const {
  const GrownBox box(lo, hi, margin);
  for (const ProjectedAxis& axis : axes_) {
    if (axis.separates(box)) return false;
  }
  return true;
}

bool TriangleBoxOverlap::plane_may_touch_box(const Vec3d& lo, const Vec3d& hi, double margin) const {
  return !axes_[0].separates(GrownBox(lo, hi, margin));
}

bool TriangleBoxOverlap::may_touch_overlapping_column(const Vec3d& lo, const Vec3d& hi, double margin,
                                                      int axis) const {
  const GrownBox box(lo, hi, margin);
  // The products of each edge with the column's axis: axes_[1 + 3 e + axis].
  for (int edge = 0; edge < 3; ++edge) {
    if (axes_[1 + 3 * edge + axis].separates(box)) return false;
  }
  return true;
}

TrianglePlaneOverlap::TrianglePlaneOverlap(const Triangle& triangle) {
  const Vec3d a(triangle.v0), b(triangle.v1), c(triangle.v2);
  normal_ = ProjectedAxis(cross(b - a, c - b), a, b, c);
}

}  // namespace outcore
