#include "core/ray/ray_problem.h"

#include <cmath>

namespace outcore {

namespace {
bool within_range(const Vec3f& v) {
  return std::fabs(v.x) <= kLargestRayComponent && std::fabs(v.y) <= kLargestRayComponent &&
         std::fabs(v.z) <= kLargestRayComponent;
}
}  // namespace

const char* ray_problem(const Ray& ray) {
  if (!is_finite(ray.origin)) return "origin is NaN or infinite";
  if (!is_finite(ray.direction)) return "direction is NaN or infinite";
  if (!within_range(ray.origin)) return "an origin component is beyond +-1.844e18 (the intersector's range)";
  if (!within_range(ray.direction))
    return "a direction component is beyond +-1.844e18 (the intersector's range)";
  if (ray.direction == Vec3f(0, 0, 0)) return "direction is zero";
  if (!std::isfinite(ray.tnear) || ray.tnear < 0.0f) return "tnear is negative, NaN or infinite";
  if (std::isnan(ray.tfar)) return "tfar is NaN";
  if (ray.tnear > ray.tfar) return "tnear > tfar";
  return nullptr;
}

}  // namespace outcore
