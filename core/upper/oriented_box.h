// OrientedBox: a box in a frame of its own around every vertex of a brick,
// fitted at pack time (stored in the manifest) and tested before a brick
// when `--brick-bounds obb` is chosen (core/upper/brick_bounds.h).
//
// Stored as three unit axes (float) and, per axis, the interval [lo, hi] of
// the vertices' projections onto it: the box is the intersection of three
// slabs, so it contains every vertex even though float axes are not exactly
// orthogonal. fit() tries candidate frames and keeps the one of least
// surface area (the cost a ray pays for a bound is roughly its area):
// the world axes (so the box is never larger than the AABB), the principal
// axes of the vertices (PCA, float64 Jacobi), and the frames of the largest
// triangles (normal, longest edge, their cross product), which find the
// orientation of thin rotated geometry that PCA of a cloud misses (a flavour
// of DiTO, Larsson & Kaellberg 2011). Projections are computed in float64
// and rounded outward with a relative pad, so every vertex is inside.
// may_hit() slabs the ray in float64 against the slabs grown by a triangle
// test's rounding bound (hit_rounding.h) and the segment widened by 2^-8 of
// its ends, as the brick proxies do: it never rejects a ray the brick's
// structure could report a hit for.
//
// Thread-safety: a plain value; const functions are pure.
#pragma once

#include <array>
#include <span>

#include "core/geometry/triangle.h"
#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct OrientedBox {
  std::array<Vec3f, 3> axes{Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)};
  std::array<float, 3> lo{1, 1, 1};  // lo > hi: empty (no vertices)
  std::array<float, 3> hi{0, 0, 0};

  static OrientedBox fit(std::span<const Triangle> triangles);
  // The box of `triangles` in the frame `axes` (unit, not necessarily
  // orthogonal).
  static OrientedBox in_frame(std::span<const Triangle> triangles, const std::array<Vec3f, 3>& axes);

  bool empty() const { return !(lo[0] <= hi[0]); }
  double volume() const;
  double surface_area() const;
  // Whether the segment [tmin, tmax] of `ray` may meet the box grown by the
  // rounding bound of a test of `rounding_scale`.
  bool may_hit(const Ray& ray, float tmin, float tmax, double rounding_scale) const;

  template <class Archive>
  void serialize(Archive& ar) {
    for (int k = 0; k < 3; ++k) ar(axes[k].x, axes[k].y, axes[k].z, lo[k], hi[k]);
  }
  bool operator==(const OrientedBox&) const = default;
};

}  // namespace outcore
