// BspPolytope: a BSP cell as a convex polytope — the intersection of
// halfspaces n_k . p <= s or >= s over the directions of bsp_directions.h —
// kept as its faces (convex polygons, counter-clockwise seen from outside)
// in float64. The builder needs cells' surface areas for the SAH, and a cell
// bounded by diagonal planes has no closed form: it starts from the root's
// box clipped by the root's k-DOP and clips one plane per level.
//
// Areas are heuristics' inputs, not bounds: rounding here may change which
// split the builder picks, never which triangles a cell keeps.
//
// Thread-safety: a plain value.
#pragma once

#include <cstdint>
#include <vector>

#include "core/geometry/vec3.h"

namespace outcore {

class BspPolytope {
 public:
  // The box [lo, hi]; empty when lo > hi on some axis.
  static BspPolytope box(const Vec3d& lo, const Vec3d& hi);

  // The part with n_k . p <= s (keep_below) or n_k . p >= s.
  BspPolytope clipped(uint32_t k, double s, bool keep_below) const;

  bool empty() const { return face_end_.empty(); }
  double area() const;
  // The range of n_k . p over the polytope ([0, 0] when empty).
  void extent(uint32_t k, double& lo, double& hi) const;
  // The surface areas of the parts below and above n_k . p = s, each with
  // the section in the plane (one pass over the faces, no new polytope).
  void split_areas(uint32_t k, double s, double& below, double& above) const;

 private:
  std::vector<Vec3d> vertices_;     // the faces' vertices, face after face
  std::vector<uint32_t> face_end_;  // one past each face's last vertex
};

}  // namespace outcore
