// Which rays the engine traces: a ray with NaN or infinite components,
// components beyond kLargestRayComponent, a zero direction, a negative or
// non-finite tnear, a NaN tfar or tnear > tfar is invalid (answered as a miss,
// or an error under --strict).
//
// Thread-safety: pure functions.
#pragma once

#include <cmath>
#include <limits>

#include "core/ray/ray_types.h"

namespace outcore {

// Why a ray is invalid, or nullptr when it is fine.
const char* ray_problem(const Ray& ray);

// ray_problem(ray) == nullptr, without its branch per rule: every valid ray
// of a batch is checked, and on a sparse scene most cost little else.
// |c| <= kLargestRayComponent is false for a NaN or infinite c, tnear >= 0 and
// tnear < inf are false for a NaN tnear, tnear <= tfar is false for a NaN
// tfar; the rules are combined with & so that all are evaluated.
inline bool ray_is_valid(const Ray& ray) {
  const auto within = [](float c) { return std::fabs(c) <= kLargestRayComponent; };
  const Vec3f& o = ray.origin;
  const Vec3f& d = ray.direction;
  const bool components = within(o.x) & within(o.y) & within(o.z) & within(d.x) & within(d.y) & within(d.z);
  const bool nonzero = (d.x != 0.0f) | (d.y != 0.0f) | (d.z != 0.0f);
  const bool segment =
      (ray.tnear >= 0.0f) & (ray.tnear < std::numeric_limits<float>::infinity()) & (ray.tnear <= ray.tfar);
  return components & nonzero & segment;
}

}  // namespace outcore
