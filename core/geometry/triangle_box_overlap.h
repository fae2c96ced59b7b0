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

#include "core/geometry/triangle.h"
#include "core/geometry/vec3.h"

namespace outcore {

// Box [lo, hi] (float64), grown by margin >= 0 on every side.
bool triangle_may_touch_box(const Triangle& triangle, const Vec3d& lo, const Vec3d& hi, double margin);

}  // namespace outcore
