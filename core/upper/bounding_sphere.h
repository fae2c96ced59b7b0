// BoundingSphere: a sphere around every vertex of a brick, fitted at pack
// time (stored in the manifest) and tested before a brick when
// `--brick-bounds sphere` is chosen (core/upper/brick_bounds.h).
//
// fit() takes the better (smaller) of two centres, the vertices' box centre
// and their mean, and the largest float64 distance from the chosen centre
// (rounded to float) to a vertex, rounded up: every vertex is inside.
// may_hit() works in float64 on the line's closest approach (not the
// quadratic's discriminant, which cancels for far ray origins), with the
// radius grown by a triangle test's rounding bound (core/geometry/
// hit_rounding.h) and the segment by 2^-8 of its ends, as the brick proxies
// do: it never rejects a ray the brick's structure could report a hit for.
//
// Thread-safety: a plain value; const functions are pure.
#pragma once

#include <span>

#include "core/geometry/triangle.h"
#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct BoundingSphere {
  Vec3f center;
  float radius = -1.0f;  // < 0: empty (no vertices)

  static BoundingSphere fit(std::span<const Triangle> triangles);

  bool empty() const { return !(radius >= 0.0f); }
  double volume() const;
  // Whether the segment [tmin, tmax] of `ray` may meet the sphere grown by
  // the rounding bound of a test of `rounding_scale`.
  bool may_hit(const Ray& ray, float tmin, float tmax, double rounding_scale) const;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(center.x, center.y, center.z, radius);
  }
  bool operator==(const BoundingSphere&) const = default;
};

}  // namespace outcore
