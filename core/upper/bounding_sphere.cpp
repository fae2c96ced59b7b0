#include "core/upper/bounding_sphere.h"

#include <cmath>
#include <limits>
#include <numbers>

#include "core/upper/bound_segment.h"

namespace outcore {
namespace {

// The largest float64 distance from `center` to a vertex.
double farthest_vertex(std::span<const Triangle> triangles, const Vec3d& center) {
  double most = 0;
  for (const Triangle& tri : triangles) {
    for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) most = std::max(most, length(Vec3d(v) - center));
  }
  return most;
}

}  // namespace

BoundingSphere BoundingSphere::fit(std::span<const Triangle> triangles) {
  BoundingSphere sphere;
  if (triangles.empty()) return sphere;
  constexpr double kInfD = std::numeric_limits<double>::infinity();
  Vec3d lo(kInfD, kInfD, kInfD), hi(-kInfD, -kInfD, -kInfD);
  Vec3d sum(0.0, 0.0, 0.0);
  for (const Triangle& tri : triangles) {
    for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
      lo = min(lo, Vec3d(v));
      hi = max(hi, Vec3d(v));
      sum = sum + Vec3d(v);
    }
  }
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float best = kInf;
  for (const Vec3d& candidate : {(lo + hi) * 0.5, sum / (3.0 * static_cast<double>(triangles.size()))}) {
    const Vec3f center(static_cast<float>(candidate.x), static_cast<float>(candidate.y),
                       static_cast<float>(candidate.z));
    const double reach = farthest_vertex(triangles, Vec3d(center));
    const float radius = std::nextafter(static_cast<float>(reach), kInf);
    if (radius < best) {
      best = radius;
      sphere = {center, radius};
    }
  }
  return sphere;
}

double BoundingSphere::volume() const {
  if (empty()) return 0;
  const double r = radius;
  return 4.0 / 3.0 * std::numbers::pi * r * r * r;
}

bool BoundingSphere::may_hit(const Ray& ray, float tmin, float tmax, double rounding_scale) const {
  if (empty()) return false;
  const Vec3d o(ray.origin), d(ray.direction), c(center);
  const double grown = radius + rounding_scale * (max_abs(o) + max_abs(c) + static_cast<double>(radius));
  const double a = dot(d, d);
  if (!(a > 0)) return true;  // not a ray the structures trace; never the bound's call
  const Vec3d oc = o - c;
  const double closest_t = -dot(oc, d) / a;
  const Vec3d closest = oc + d * closest_t;
  const double miss2 = grown * grown - dot(closest, closest);
  if (miss2 < 0) return false;
  const double half = std::sqrt(miss2 / a);
  return bound_segment_overlaps(closest_t - half, closest_t + half, tmin, tmax);
}

}  // namespace outcore
