// Secondary-ray origins: where to start a shadow, bounce or transmission ray
// from a hit so that it neither re-hits its own triangle (self-intersection,
// "shadow acne") nor skips a neighbour that is truly close. In the spirit of
// Wächter & Binder 2019 ("A Fast and Robust Method for Avoiding
// Self-Intersection", Ray Tracing Gems ch. 6): move the hit point off the
// surface along the geometric normal by a distance that scales with the
// magnitudes involved, not by a fixed epsilon.
//
// Wächter & Binder compute the hit point from barycentrics, whose error is a
// few ulps of |p|. A remote client only has the ray and t, so the point here is
// o + t d, evaluated in float64; its error is dominated by the error of the
// float t the triangle test returned, which is relative to the distances the
// test worked with (|o|, |p| and t |d|: the watertight tests translate to the
// ray origin; the worst measured relative t error over the stress suite is
// 3.4e-6, docs/ACCURACY.md). The offset is therefore
//     delta = kSpawnRelativeOffset * (|o|_inf + |p|_inf + t |d|_inf)
// (2^-16, about 1.5e-5, over 4x the worst measured error) plus a tiny absolute
// floor, applied along +-ng in float64 and rounded once to float. The side:
// kFront is the side the ray arrived from (shadow rays, reflections), kBack the
// other (transmission). A neighbour nearer than delta to the hit point may be
// skipped; nothing farther is (tested in spawn_origin_test.cpp).
//
// The Python client implements the same formula (outcore.spawn_origins) with
// bitwise equal results; `outcore trace --spawn-out FILE` writes them.
//
// Thread-safety: pure functions.
#pragma once

#include <cmath>
#include <limits>

#include "core/ray/ray_types.h"

namespace outcore {

inline constexpr double kSpawnRelativeOffset = 0x1p-16;
// Keeps the offset positive for hits at the origin of a zero-length segment.
inline constexpr double kSpawnAbsoluteOffset = 0x1p-120;

enum class SpawnSide { kFront, kBack };

// The origin for the next ray from `hit` of `ray`; NaN in every component for
// a miss (so it can never be used by accident).
inline Vec3f spawn_origin(const Ray& ray, const Hit& hit, SpawnSide side) {
  if (!hit.is_hit()) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    return {nan, nan, nan};
  }
  const Vec3d o(ray.origin), d(ray.direction), n(hit.normal);
  const double t = hit.t;
  const Vec3d p = o + d * t;
  const double delta =
      kSpawnRelativeOffset * (max_abs(o) + max_abs(p) + t * max_abs(d)) + kSpawnAbsoluteOffset;
  // Front: against the incoming direction, i.e. the normal's side when the ray
  // hit the front face (d . n < 0).
  const bool front_is_along_normal = dot(d, n) < 0.0;
  const double sign = (side == SpawnSide::kFront) == front_is_along_normal ? 1.0 : -1.0;
  return Vec3f(p + n * (sign * delta));
}

}  // namespace outcore
