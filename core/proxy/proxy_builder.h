// Proxy builder: voxelises one brick's triangles into a conservative
// occupancy proxy (brick_proxy.h). The voxel size is chosen so that the
// brick box's longest side spans `resolution` voxels; the grid's domain is
// the box plus one voxel on every side. A voxel is occupied when its box,
// grown by the margin, overlaps a triangle — an exact
// separating-axis test in float64 (Akenine-Möller 2001: the box's 3 axes,
// the triangle's normal and the 9 edge x axis products). So every point
// within the margin of any triangle lies in an occupied voxel; degenerate
// (zero-area) triangles are handled as the segments or points they are.
//
// The margin is a quarter voxel, grown (up to one voxel) until it is at
// least twice the watertight test's rounding bound E (brick_proxy.h) of a
// ray starting anywhere within proxy_origin_reach() of the scene: E grows
// with the distance from the world origin, and a quarter voxel of a small
// brick far from it could otherwise be below 2E for every ray, so the proxy
// could never answer "no hit".
//
// Thread-safety: pure functions; may run on many bricks at once.
#pragma once

#include <cstdint>
#include <span>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/proxy/brick_proxy.h"
#include "core/util/status.h"

namespace outcore {

inline constexpr uint32_t kMinProxyResolution = 1;
inline constexpr uint32_t kMaxProxyResolution = 256;
// The margin around every triangle, in voxels: at least the first (recorded
// in proxies.bin), at most the second.
inline constexpr double kProxyMarginVoxels = 0.25;
inline constexpr double kMaxProxyMarginVoxels = 1.0;

struct ProxyBuildConfig {
  // Voxels along the longest side of each brick's box, in
  // [kMinProxyResolution, kMaxProxyResolution]. 32 keeps a proxy at a few
  // KiB and a march at a few dozen voxel steps.
  uint32_t resolution = 32;
};

// INVALID_ARGUMENT naming the option when the resolution is out of range.
Status validate_proxy_config(const ProxyBuildConfig& config);

// The largest |coordinate| of a ray origin the margins are sized for: any
// point of the scene's box grown by its longest side on every side.
double proxy_origin_reach(const Aabb& scene_bounds_WS);

// The frame (voxel size, domain, margin) of a brick with these bounds in a
// scene with those.
ProxyFrame proxy_frame_for(const Aabb& brick_bounds_WS, const Aabb& scene_bounds_WS,
                           const ProxyBuildConfig& config);

BrickProxy build_brick_proxy(const Aabb& brick_bounds_WS, const Aabb& scene_bounds_WS,
                             std::span<const Triangle> triangles, const ProxyBuildConfig& config);

// Exact (float64) separating-axis test: does the triangle (a, b, c) overlap
// the closed box centre +- half?
bool triangle_overlaps_box(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& centre,
                           const Vec3d& half);

}  // namespace outcore
