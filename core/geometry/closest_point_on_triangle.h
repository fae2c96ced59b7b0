// closest_point_on_triangle: the point of a triangle nearest to a query point,
// in float64, with its barycentrics, by the Voronoi-region walk of Ericson,
// "Real-Time Collision Detection" 5.1.5. Point queries (compute_closest_points,
// compute_distance) rank candidates by its squared distance, so that the
// answer does not depend on the structure that found the triangle.
//
// Thread-safety: a pure function.
#pragma once

#include "core/geometry/triangle.h"
#include "core/geometry/vec3.h"

namespace outcore {

struct TrianglePoint {
  Vec3d point;
  double u = 0;  // barycentrics as a hit's: point = (1-u-v) v0 + u v1 + v v2
  double v = 0;
  double distance_squared = 0;
};

inline TrianglePoint closest_point_on_triangle(const Vec3d& p, const Triangle& tri) {
  const Vec3d a(tri.v0), b(tri.v1), c(tri.v2);
  const Vec3d ab = b - a, ac = c - a, ap = p - a;
  auto at = [&](double u, double v) {
    const Vec3d q = a + ab * u + ac * v;
    const Vec3d d = p - q;
    return TrianglePoint{q, u, v, dot(d, d)};
  };
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return at(0, 0);
  const Vec3d bp = p - b;
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return at(1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
  const Vec3d cp = p - c;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return at(0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return at(1 - w, w);  // on edge bc
  }
  const double denom = 1 / (va + vb + vc);
  return at(vb * denom, vc * denom);
}

// Squared distance from p to the box (0 inside), in float64.
inline double distance_squared_to_box(const Vec3d& p, const Aabb& box) {
  double sum = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double lo = box.lo[axis], hi = box.hi[axis];
    const double d = p[axis] < lo ? lo - p[axis] : (p[axis] > hi ? p[axis] - hi : 0.0);
    sum += d * d;
  }
  return sum;
}

}  // namespace outcore
