// The largest vertex coordinate a scene may have, and the check the readers
// and the packer share. Why 2^39 (about 5.5e11), far below Embree's limit of
// 1.844e18 (beyond which it drops a triangle silently): the float triangle
// tests multiply three coordinate differences (the watertight test's
// t = (u az + v bz + w cz) / det, with u ~ (edge)^2, Moeller-Trumbore's
// dot(Ng, v0 - o)), so with coordinates and ray origins within +-L the
// products reach about 333 L^3 / |d| for a unit-length ray direction d and
// overflow FLT_MAX (3.4e38) from L ~ 1.0e12: Embree and bvh then miss hits
// the float64 reference finds (measured from 4e12; docs/ACCURACY.md). 2^39
// keeps a margin of 6 for directions down to 1/6 in length, and is exact in
// float, so the comparison rounds nothing.
//
// Thread-safety: constants and pure functions.
#pragma once

#include <cmath>

#include "core/geometry/triangle.h"

namespace outcore {

inline constexpr float kLargestVertexComponent = 0x1p39f;
// For messages.
inline constexpr char kLargestVertexComponentText[] = "+-5.5e11 (2^39)";

inline bool within_vertex_range(float c) {
  return std::fabs(c) <= kLargestVertexComponent;
}

// Why a triangle cannot be packed, or nullptr.
inline const char* vertex_problem(const Triangle& t) {
  if (!t.is_finite()) return "has a NaN or infinite coordinate";
  for (const Vec3f& v : {t.v0, t.v1, t.v2}) {
    if (!within_vertex_range(v.x) || !within_vertex_range(v.y) || !within_vertex_range(v.z))
      return "has a coordinate beyond +-5.5e11 (2^39), the largest the float ray/triangle tests handle "
             "(docs/INPUTS.md)";
  }
  return nullptr;
}

}  // namespace outcore
