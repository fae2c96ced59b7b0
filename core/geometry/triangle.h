// Triangle: three float vertices exactly as the user's input gave them (after
// parsing to float32), and PackedTriangle, a triangle tagged with the ids the
// user knows it by (geometry_id = position on the pack command line,
// primitive_id = index within that input after fan triangulation / strip
// expansion). PackedTriangle is also the on-disk spill record, so its layout is
// fixed (44 bytes, no padding).
//
// Thread-safety: plain values.
#pragma once

#include <cstdint>

#include "core/geometry/aabb.h"

namespace outcore {

struct Triangle {
  Vec3f v0, v1, v2;

  Aabb bounds() const {
    Aabb b;
    b.extend(v0);
    b.extend(v1);
    b.extend(v2);
    return b;
  }
  // Centroid computed in float the same way everywhere, so partition decisions
  // made in different passes agree bit for bit.
  Vec3f centroid() const { return (v0 + v1 + v2) * (1.0f / 3.0f); }
  bool is_finite() const {
    return outcore::is_finite(v0) && outcore::is_finite(v1) && outcore::is_finite(v2);
  }
  // Zero area in float64 (collinear or repeated vertices).
  bool is_degenerate() const {
    const Vec3d a(v0), b(v1), c(v2);
    const Vec3d n = cross(b - a, c - a);
    return n.x == 0.0 && n.y == 0.0 && n.z == 0.0;
  }
  // The unit geometric normal every brick structure reports (Embree's Ng
  // orientation), computed in float64 and rounded, so it does not depend on
  // the structure or on where the triangle is stored.
  Vec3f unit_normal() const {
    const Vec3d a(v0), b(v1), c(v2);
    return Vec3f(normalize(cross(b - a, c - a)));
  }
  bool operator==(const Triangle&) const = default;
};
static_assert(sizeof(Triangle) == 36);

struct PackedTriangle {
  Triangle tri;
  uint32_t geometry_id;
  uint32_t primitive_id;
};
static_assert(sizeof(PackedTriangle) == 44);

}  // namespace outcore
