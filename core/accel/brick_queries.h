// The queries beyond closest and any hit that a brick answers: every hit
// along a ray (Open3D's count_intersections / list_intersections) and the
// closest point of its triangles to a point (compute_closest_points and the
// distances built on it), with the exact scans that any structure keeping its
// triangles in an array can use (brute force over one brick; the bvh walks
// its tree instead, wide_bvh_queries.h).
//
// Every hit: each triangle the ray hits with tnear < t <= tfar, once, by the
// brick's triangle test; a brick holds each triangle once, so hits over all
// the bricks a ray's segment enters are the scene's hits, each once.
// Closest point: float64 (closest_point_on_triangle.h), ties at equal squared
// distance to the smaller (geometry_id, primitive_id), so the answer is the
// same whatever order bricks come in.
//
// Thread-safety: pure functions over immutable bricks; callers give each
// thread its own output.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/bvh/triangle_hit.h"
#include "core/geometry/closest_point_on_triangle.h"
#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"

namespace outcore {

// One hit of one ray in an every-hit query.
struct RayHitRecord {
  uint32_t ray;
  Hit hit;
};

// The best point found so far for one query point.
struct ClosestPoint {
  double distance_squared = std::numeric_limits<double>::infinity();
  Vec3f point;
  uint32_t geometry_id = kInvalidId;
  uint32_t primitive_id = kInvalidId;
  float u = 0;
  float v = 0;
  Vec3f normal;

  bool found() const { return primitive_id != kInvalidId; }
};

inline bool closest_is_better(double distance_squared, uint32_t geometry_id, uint32_t primitive_id,
                              const ClosestPoint& current) {
  if (distance_squared != current.distance_squared) return distance_squared < current.distance_squared;
  if (geometry_id != current.geometry_id) return geometry_id < current.geometry_id;
  return primitive_id < current.primitive_id;
}

// Offers `tri` (with its ids and unit normal) to `best` for query point p.
inline void offer_closest(const Vec3d& p, const Triangle& tri, uint32_t geometry_id, uint32_t primitive_id,
                          const Vec3f& normal, ClosestPoint& best) {
  const TrianglePoint found = closest_point_on_triangle(p, tri);
  if (!closest_is_better(found.distance_squared, geometry_id, primitive_id, best)) return;
  best = {found.distance_squared,      Vec3f(found.point),          geometry_id, primitive_id,
          static_cast<float>(found.u), static_cast<float>(found.v), normal};
}

inline Hit hit_of(const TriangleHit& found, uint32_t geometry_id, uint32_t primitive_id,
                  const Vec3f& normal) {
  return {found.t, geometry_id, primitive_id, found.u, found.v, normal};
}

// A triangle kept for its index but never answered (zero-area in float64:
// its record's normal is zero; the float64 reference skips it too).
inline bool is_degenerate_record(const BvhHitRecord& r) {
  return r.normal.x == 0 && r.normal.y == 0 && r.normal.z == 0;
}

// Every hit of the rays `ray_ids` on the triangles (records[k] belongs to
// triangles[k]), appended to `out`.
template <class Test>
void all_hits_by_scan(std::span<const Triangle> triangles, std::span<const BvhHitRecord> records,
                      std::span<const uint32_t> ray_ids, const Ray* rays, std::vector<RayHitRecord>& out) {
  for (const uint32_t i : ray_ids) {
    const Ray& ray = rays[i];
    const typename Test::Prepared prepared = Test::prepare(ray);
    for (std::size_t k = 0; k < triangles.size(); ++k) {
      TriangleHit found;
      if (!Test::hit(prepared, triangles[k], ray.tnear, ray.tfar, found)) continue;
      const BvhHitRecord& r = records[k];
      if (is_degenerate_record(r)) continue;
      out.push_back({i, hit_of(found, r.geometry_id, r.primitive_id, r.normal)});
    }
  }
}

// Improves best[i] for each i in point_ids with the triangles' closest points.
inline void closest_points_by_scan(std::span<const Triangle> triangles, std::span<const BvhHitRecord> records,
                                   std::span<const uint32_t> point_ids, const Vec3f* points,
                                   ClosestPoint* best) {
  for (const uint32_t i : point_ids) {
    const Vec3d p(points[i]);
    for (std::size_t k = 0; k < triangles.size(); ++k) {
      const BvhHitRecord& r = records[k];
      if (is_degenerate_record(r)) continue;
      offer_closest(p, triangles[k], r.geometry_id, r.primitive_id, r.normal, best[i]);
    }
  }
}

}  // namespace outcore
