// Proxy builder: voxelises one brick's triangles into a conservative
// occupancy proxy (brick_proxy.h). The voxel size is chosen so that the
// brick box's longest side spans `resolution` voxels; the grid's domain is
// the box plus one voxel on every side. A voxel is occupied when its box,
// grown by the margin (a quarter voxel), overlaps a triangle — an exact
// separating-axis test in float64 (Akenine-Möller 2001: the box's 3 axes,
// the triangle's normal and the 9 edge x axis products). So every point
// within the margin of any triangle lies in an occupied voxel; degenerate
// (zero-area) triangles are handled as the segments or points they are.
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
// The margin around every triangle, in voxels (recorded in proxies.bin).
inline constexpr double kProxyMarginVoxels = 0.25;

struct ProxyBuildConfig {
  // Voxels along the longest side of each brick's box, in
  // [kMinProxyResolution, kMaxProxyResolution]. 32 keeps a proxy at a few
  // KiB and a march at a few dozen voxel steps.
  uint32_t resolution = 32;
};

// INVALID_ARGUMENT naming the option when the resolution is out of range.
Status validate_proxy_config(const ProxyBuildConfig& config);

// The frame (voxel size, domain, margin) of a brick with these bounds.
ProxyFrame proxy_frame_for(const Aabb& bounds_WS, const ProxyBuildConfig& config);

BrickProxy build_brick_proxy(const Aabb& bounds_WS, std::span<const Triangle> triangles,
                             const ProxyBuildConfig& config);

// Exact (float64) separating-axis test: does the triangle (a, b, c) overlap
// the closed box centre +- half?
bool triangle_overlaps_box(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& centre,
                           const Vec3d& half);

}  // namespace outcore
