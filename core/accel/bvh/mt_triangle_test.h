// Möller–Trumbore (1997) in float: the classic fast test. Not watertight: a
// ray through a shared edge or vertex can fall between the adjacent triangles
// because each computes its barycentrics with its own rounding (the stress
// suite measures how often). Kept as the speed baseline of the run-time vs
// error comparison.
//
// Thread-safety: pure functions.
#pragma once

#include <string_view>

#include "core/accel/bvh/triangle_hit.h"
#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct MtTriangleTest {
  static constexpr std::string_view kName = "mt";

  struct Prepared {
    Vec3f origin;
    Vec3f direction;
  };

  static Prepared prepare(const Ray& ray) { return {ray.origin, ray.direction}; }

  static bool hit(const Prepared& ray, const Triangle& tri, float tnear, float tfar, TriangleHit& out) {
    const Vec3f e1 = tri.v1 - tri.v0;
    const Vec3f e2 = tri.v2 - tri.v0;
    const Vec3f p = cross(ray.direction, e2);
    const float det = dot(e1, p);
    if (det == 0.0f) return false;  // the ray is parallel to the plane
    const float inv = 1.0f / det;
    const Vec3f s = ray.origin - tri.v0;
    const float u = dot(s, p) * inv;
    if (!(u >= 0.0f && u <= 1.0f)) return false;
    const Vec3f q = cross(s, e1);
    const float v = dot(ray.direction, q) * inv;
    if (!(v >= 0.0f && u + v <= 1.0f)) return false;
    const float t = dot(e2, q) * inv;
    if (!(t > tnear && t <= tfar)) return false;
    out = {t, u, v};
    return true;
  }
};

}  // namespace outcore
