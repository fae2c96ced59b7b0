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

// The margin a structure grows its cells by when it files triangles into
// cells of `cell_size` within `region` (the grid's, an octree node's
// children): 2^-20 of the cell size plus the coordinates' magnitude, far
// above float64 rounding and far below a cell, so the test stays
// conservative without filing triangles into distant cells.
double cell_filing_margin(const Aabb& region, const Vec3d& cell_size);

}  // namespace outcore
