// AffineTransform: where an instance of a mesh sits in the world — world =
// L * object + offset, given as a row-major 3x4 matrix (the last column the
// offset), as the dynamic layer's API and `outcore trace --dynamic` take it.
// Rigid, scaled, sheared and mirrored placements are all affine; singular or
// non-finite ones are refused (from_rows) because a ray could not be taken
// into the instance's frame.
//
// Everything is computed in double: a ray goes into the object frame with
// the inverse (to_object), a hit's normal comes back with the inverse
// transpose, and a world box is the image of an object box widened so that
// it holds the image of everything in the object box whatever the rounding.
//
// Thread-safety: plain values.
#pragma once

#include <array>
#include <span>
#include <string>

#include "core/geometry/aabb.h"
#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"
#include "core/util/status.h"

namespace outcore {

struct AffineTransform {
  std::array<std::array<double, 4>, 3> m{{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};

  // The 12 numbers row by row. INVALID_ARGUMENT (naming `what`) when one is
  // not finite, or the linear part is singular: |det L| <= 1e-12 x the
  // product of its rows' lengths (a placement that flattens the mesh).
  static Expected<AffineTransform> from_rows(std::span<const double> rows, const std::string& what);
  static Expected<AffineTransform> from_rows(std::span<const float> rows, const std::string& what);

  Vec3d point(const Vec3d& p) const;
  Vec3d vector(const Vec3d& v) const;
  double determinant() const;
  // Precondition: non-singular (from_rows checked it).
  AffineTransform inverse() const;
  bool is_identity() const;
  // |L| |L^-1| (Frobenius norms): how much a relative rounding error of a
  // ray taken into the object frame can grow when seen in the world.
  double condition_number() const;

  // A box holding the image of every point of `object` (its 8 corners in
  // double, rounded outward to float). A ray tested against it in the world
  // must be given the slack of its own trip into the object frame
  // (condition_number()).
  Aabb world_box(const Aabb& object) const;
  // This transform is the world-to-object one: the ray in the object frame,
  // same t (the direction is mapped, not normalised).
  Ray ray_to_object(const Ray& world) const;
  // This transform is the world-to-object one: a unit object normal as a unit
  // world normal (its transpose applied, in double, normalised, rounded).
  Vec3f normal_to_world(const Vec3f& object_normal) const;
};

}  // namespace outcore
