// BrickProxy: a conservative occupancy grid over one brick (an OpenVDB mask
// tree, core/proxy/proxy_grid.h) plus its world-to-index frame, kept resident
// so the engine can tell, without loading the brick, that a ray cannot hit
// anything in it (cf. Molenaar & Eisemann 2020, "Conservative Ray Batching
// using Geometry Proxies"). Built by proxy_builder.h; all bricks' proxies
// live in a ProxySet (proxy_set.h).
//
// may_hit(ray, tmin, tmax, rounding_scale) marches the ray's segment through
// the grid with OpenVDB's DDA, hierarchically (8^3-voxel leaves first, then
// the voxels of each occupied leaf, like openvdb::math::LevelSetHDDA), and
// answers false only when the segment touches no occupied voxel. It never
// answers false for a ray the brick structure could report a hit for, as far
// as its triangle test's rounding is bounded:
//   - every voxel within margin_WS (>= a quarter voxel) of a triangle is
//     occupied (the builder's guarantee);
//   - the segment is widened by 2^-8 of its ends (relative) plus the rounding
//     bound E below, so a hit a brick structure reports at t <= tmax has its
//     exact point inside the marched segment, also for grazing rays whose
//     float t is far less accurate than their position;
//   - E = rounding_scale * (|origin|inf + |brick coordinates|inf) is how far
//     the exact ray may pass from a triangle the structure's float test
//     accepts. The watertight test (and the float64 one) translate the
//     vertices to the ray origin and shear them into the ray's frame, so what
//     they accept is the exact triangle with vertices moved by a few float
//     epsilons of those magnitudes, whatever the triangle's shape or the
//     ray's angle: kWatertightHitRounding = 2^-19 (16 epsilons; the largest
//     measured by proxy_rounding_test.cpp is 0.6). Moeller-Trumbore tests
//     (Embree's, robust or not, and bvh's mt) have no such bound: their edge
//     and denominator terms cancel for grazing rays, and they accept rays
//     hundreds of epsilons from a triangle (up to ~800 measured for Embree's
//     robust mode on thin triangles). kMollerTrumboreHitRounding = 2^-15
//     covers their non-grazing acceptances; a hit such a test reports farther
//     than the margin from every triangle (one the exact ray misses, which
//     the float64 reference and the watertight test call a miss) may be
//     skipped by the proxy. When E exceeds half the margin (a brick small
//     against its distance from the origin or from the ray origin) the
//     answer is true: the grid cannot decide, the brick is traced. The
//     builder grows the margin (up to a voxel) so that the watertight 2E fits
//     every ray origin within proxy_origin_reach() of the scene
//     (proxy_builder.h).
//   - the march runs in float64, whose rounding is far below E.
//
// Thread-safety: immutable after construction; may_hit() and all const
// functions may be called from any number of threads at once (each call uses
// its own leaf cache on the stack; no allocation, no locks).
#pragma once

#include <array>
#include <cstdint>
#include <memory>

#include "core/geometry/hit_rounding.h"
#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"

namespace outcore {

// Index space <-> world space of one proxy (names carry the frame: ...WS
// world space, ...IS index space). Voxel (i, j, k) covers the world box
// origin_WS + [i, i+1) x [j, j+1) x [k, k+1) * voxel_size_WS.
struct ProxyFrame {
  Vec3d origin_WS;
  double voxel_size_WS = 0;
  std::array<int32_t, 3> dims_IS{0, 0, 0};  // voxels per axis; the domain is [0, dims)
  double margin_WS = 0;                     // the builder's margin around every triangle

  Vec3d index_to_world(const Vec3d& p_IS) const { return origin_WS + p_IS * voxel_size_WS; }
  Vec3d world_to_index(const Vec3d& p_WS) const { return (p_WS - origin_WS) / voxel_size_WS; }
  // The largest |coordinate| of the grid's domain (the |brick| term of E).
  double domain_magnitude_WS() const;
};

// E of the header comment: how far the exact ray may pass from a triangle a
// float ray/triangle test accepts, for a test of this rounding scale, a ray
// origin of largest |coordinate| `origin_magnitude_WS` and a domain of
// `domain_magnitude_WS`.
inline double proxy_rounding_bound(double rounding_scale, double origin_magnitude_WS,
                                   double domain_magnitude_WS) {
  return rounding_scale * (origin_magnitude_WS + domain_magnitude_WS);
}

class BrickProxy {
 public:
  struct Impl;  // core/proxy/proxy_grid.h

  BrickProxy();
  explicit BrickProxy(std::unique_ptr<Impl> impl);
  ~BrickProxy();
  BrickProxy(BrickProxy&&) noexcept;
  BrickProxy& operator=(BrickProxy&&) noexcept;

  // False only when no part of the ray's segment [tmin, tmax] (in units of
  // the direction's length) can reach a triangle of the brick; see above for
  // rounding_scale (BrickBuilder::hit_rounding_scale()).
  bool may_hit(const Ray& ray, float tmin, float tmax, double rounding_scale) const;

  const ProxyFrame& frame() const;
  bool is_occupied(int32_t i, int32_t j, int32_t k) const;
  uint64_t active_voxels() const;
  // Resident bytes: the OpenVDB tree's nodes plus this object's own.
  uint64_t memory_bytes() const;

  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace outcore
