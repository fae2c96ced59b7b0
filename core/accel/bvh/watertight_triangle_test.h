// Watertight ray/triangle test of Woop, Benthin & Wald 2013 ("Watertight
// Ray/Triangle Intersection", JCGT 2(1)), in float, with the paper's
// double-precision fallback. The ray is sheared so that it becomes the +z
// axis through the origin; the test is then three 2D edge functions of the
// transformed vertices. A vertex is transformed the same way whichever
// triangle it belongs to, and an edge shared by two triangles gives the same
// edge function up to sign (no fused multiply-add: the build uses
// -march=x86-64-v2 and ISO C++, so GCC does not contract), so a ray through a
// shared edge or vertex is inside at least one of the adjacent triangles: no
// leaks. Edges and vertices count as inside; both facings are hit.
//
// Fallback: an edge function that is exactly 0 in float may be the rounding of
// a tiny value of either sign; it is recomputed in double, where the product
// of two floats is exact, so its sign is exact. A non-zero float edge function
// already has the exact sign (rounding is monotonic), so neighbours that take
// different paths still agree.
//
// Thread-safety: pure functions.
#pragma once

#include <cmath>
#include <cstring>
#include <string_view>
#include <utility>

#include "core/accel/bvh/triangle_hit.h"
#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct WatertightTriangleTest {
  static constexpr std::string_view kName = "watertight";

  struct Prepared {
    float ox, oy, oz;  // origin, permuted: x, y across the ray, z along it
    float sx, sy, sz;  // shear and scale
    int kx, ky, kz;    // permutation of the axes
    Vec3f direction;
  };

  // The permutation alone (no division): kz the direction's largest axis.
  struct Axes {
    int kx, ky, kz;
    bool operator==(const Axes&) const = default;
  };
  static Axes axes(const Vec3f& d) {
    const float ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
    const int kz = (ax >= ay && ax >= az) ? 0 : (ay >= az ? 1 : 2);
    int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
    if (d[kz] < 0.0f) std::swap(kx, ky);  // keeps the winding of the transformed triangle
    return {kx, ky, kz};
  }

  static Prepared prepare(const Ray& ray) {
    const Vec3f d = ray.direction;
    const auto [kx, ky, kz] = axes(d);
    Prepared p;
    p.kx = kx;
    p.ky = ky;
    p.kz = kz;
    p.sx = d[kx] / d[kz];
    p.sy = d[ky] / d[kz];
    p.sz = 1.0f / d[kz];
    p.ox = ray.origin[kx];
    p.oy = ray.origin[ky];
    p.oz = ray.origin[kz];
    p.direction = d;
    return p;
  }

  // A ray parallel to the triangle's plane: the triple product of the
  // direction and the edges is 0 in double (exact for the coplanar
  // configurations of grid-aligned and quantised meshes). The edge functions
  // of such a ray are rounding noise that can all share a sign, and would
  // report a "hit" at a meaningless t; the exact test rejects it. Evaluated
  // only for candidates that passed the edge tests. Watertightness is kept:
  // the triangle's projection is then a segment, covered by its neighbours'
  // edges, which count as inside.
  static bool in_plane(const Vec3f& direction, const Triangle& tri) {
    const Vec3d v0(tri.v0);
    const Vec3d n = cross(Vec3d(tri.v1) - v0, Vec3d(tri.v2) - v0);
    return dot(Vec3d(direction), n) == 0.0;
  }

  static bool hit(const Prepared& r, const Triangle& tri, float tnear, float tfar, TriangleHit& out) {
    float c[9];
    std::memcpy(c, &tri, sizeof(c));
    // Vertices relative to the origin, permuted, then sheared.
    const float az_ = c[r.kz] - r.oz, bz_ = c[3 + r.kz] - r.oz, cz_ = c[6 + r.kz] - r.oz;
    const float ax = (c[r.kx] - r.ox) - r.sx * az_;
    const float ay = (c[r.ky] - r.oy) - r.sy * az_;
    const float bx = (c[3 + r.kx] - r.ox) - r.sx * bz_;
    const float by = (c[3 + r.ky] - r.oy) - r.sy * bz_;
    const float cx = (c[6 + r.kx] - r.ox) - r.sx * cz_;
    const float cy = (c[6 + r.ky] - r.oy) - r.sy * cz_;
    float u = cx * by - cy * bx;
    float v = ax * cy - ay * cx;
    float w = bx * ay - by * ax;
    if (u == 0.0f || v == 0.0f || w == 0.0f) {
      u = static_cast<float>(double{cx} * double{by} - double{cy} * double{bx});
      v = static_cast<float>(double{ax} * double{cy} - double{ay} * double{cx});
      w = static_cast<float>(double{bx} * double{ay} - double{by} * double{ax});
    }
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
    const float det = u + v + w;
    if (det == 0.0f) return false;  // the ray lies in the triangle's plane
    if (in_plane(r.direction, tri)) return false;
    const float t = (u * (r.sz * az_) + v * (r.sz * bz_) + w * (r.sz * cz_)) / det;
    if (!(t > tnear && t <= tfar)) return false;
    const float inv = 1.0f / det;
    out = {t, v * inv, w * inv};
    return true;
  }
};

}  // namespace outcore
