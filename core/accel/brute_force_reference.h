// Brute-force float64 reference for ray queries: every fast path (brick
// structures, the engine, the server) is tested against it. Möller–Trumbore in
// double over every triangle, the same segment rule as Embree (a hit at t
// counts when tnear < t <= tfar; edges and vertices count as inside), and
// hit_is_better()'s tie rule over all triangles (equal t -> smaller
// (geometry_id, primitive_id)); fast paths may pick another triangle at a
// true tie (equal float t, e.g. inside one Embree brick), which tests allow.
// Triangles that are degenerate in float64 are never hit.
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <span>

#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"
#include "core/store/brick_data.h"

namespace outcore {

// A hit in float64: t in units of the ray direction's length, Embree's
// barycentrics (p = (1-u-v) v0 + u v1 + v v2), unit normal
// normalize(cross(v1 - v0, v2 - v0)).
struct ReferenceHit {
  double t = std::numeric_limits<double>::infinity();
  uint32_t geometry_id = kInvalidId;
  uint32_t primitive_id = kInvalidId;
  double u = 0, v = 0;
  Vec3d normal;

  bool is_hit() const { return primitive_id != kInvalidId; }
};

// The ray's intersection with the triangle's plane and its barycentrics,
// without the inside and segment tests (nullopt when parallel or degenerate):
// what a test needs to judge a near-edge disagreement.
struct PlaneHit {
  double t, u, v;
};
inline std::optional<PlaneHit> reference_plane_hit(const Triangle& tri, const Ray& ray) {
  const Vec3d v0(tri.v0), v1(tri.v1), v2(tri.v2);
  const Vec3d o(ray.origin), d(ray.direction);
  const Vec3d e1 = v1 - v0, e2 = v2 - v0;
  const Vec3d n = cross(e1, e2);
  if (n.x == 0.0 && n.y == 0.0 && n.z == 0.0) return std::nullopt;  // degenerate (Triangle::is_degenerate)
  const Vec3d p = cross(d, e2);
  const double det = dot(e1, p);
  if (det == 0.0) return std::nullopt;
  const double inv = 1.0 / det;
  const Vec3d s = o - v0;
  const Vec3d q = cross(s, e1);
  return PlaneHit{dot(e2, q) * inv, dot(s, p) * inv, dot(d, q) * inv};
}

// The ray's hit on one triangle, or nullopt.
inline std::optional<PlaneHit> reference_triangle_hit(const Triangle& tri, const Ray& ray) {
  const auto h = reference_plane_hit(tri, ray);
  if (!h || h->u < 0.0 || h->v < 0.0 || h->u + h->v > 1.0) return std::nullopt;
  if (!(h->t > static_cast<double>(ray.tnear) && h->t <= static_cast<double>(ray.tfar))) return std::nullopt;
  return h;
}

inline Vec3d reference_unit_normal(const Triangle& tri) {
  const Vec3d v0(tri.v0), v1(tri.v1), v2(tri.v2);
  return normalize(cross(v1 - v0, v2 - v0));
}

// Closest hit over all triangles (ids[k] names triangles[k]).
inline ReferenceHit reference_closest_hit(std::span<const Triangle> triangles,
                                          std::span<const TriangleId> ids, const Ray& ray) {
  ReferenceHit best;
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    const auto h = reference_triangle_hit(triangles[k], ray);
    if (!h) continue;
    const TriangleId id = ids[k];
    const bool better = h->t != best.t
                            ? h->t < best.t
                            : (id.geometry_id != best.geometry_id ? id.geometry_id < best.geometry_id
                                                                  : id.primitive_id < best.primitive_id);
    if (!better) continue;
    best.t = h->t;
    best.geometry_id = id.geometry_id;
    best.primitive_id = id.primitive_id;
    best.u = h->u;
    best.v = h->v;
    best.normal = reference_unit_normal(triangles[k]);
  }
  return best;
}

// Any hit over all triangles.
inline bool reference_any_hit(std::span<const Triangle> triangles, const Ray& ray) {
  for (const Triangle& tri : triangles) {
    if (reference_triangle_hit(tri, ray)) return true;
  }
  return false;
}

}  // namespace outcore
