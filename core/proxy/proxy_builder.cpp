#include "core/proxy/proxy_builder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/proxy/proxy_grid.h"

namespace outcore {

namespace {

// One separating axis: do the triangle's projections [min p, max p] and the
// box's [-r, r] overlap?
bool overlaps_on_axis(const Vec3d& axis, const Vec3d& v0, const Vec3d& v1, const Vec3d& v2,
                      const Vec3d& half) {
  const double p0 = dot(axis, v0), p1 = dot(axis, v1), p2 = dot(axis, v2);
  const double r = half.x * std::fabs(axis.x) + half.y * std::fabs(axis.y) + half.z * std::fabs(axis.z);
  return !(std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r);
}

}  // namespace

Status validate_proxy_config(const ProxyBuildConfig& config) {
  if (config.resolution < kMinProxyResolution || config.resolution > kMaxProxyResolution) {
    return invalid_argument("proxy resolution must be between " + std::to_string(kMinProxyResolution) +
                            " and " + std::to_string(kMaxProxyResolution) + ", got " +
                            std::to_string(config.resolution));
  }
  return Status::Ok();
}

bool triangle_overlaps_box(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& centre,
                           const Vec3d& half) {
  const Vec3d v0 = a - centre, v1 = b - centre, v2 = c - centre;
  // The box's own axes: the triangle's bounds against the box.
  for (int axis = 0; axis < 3; ++axis) {
    if (std::min({v0[axis], v1[axis], v2[axis]}) > half[axis]) return false;
    if (std::max({v0[axis], v1[axis], v2[axis]}) < -half[axis]) return false;
  }
  const Vec3d e0 = v1 - v0, e1 = v2 - v1, e2 = v0 - v2;
  // The triangle's plane (a zero normal, for a degenerate triangle, separates nothing).
  const Vec3d normal = cross(e0, v2 - v0);
  if (!overlaps_on_axis(normal, v0, v1, v2, half)) return false;
  // Edge x box-axis products (a zero product separates nothing either).
  const Vec3d units[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (const Vec3d& edge : {e0, e1, e2}) {
    for (const Vec3d& unit : units) {
      if (!overlaps_on_axis(cross(unit, edge), v0, v1, v2, half)) return false;
    }
  }
  return true;
}

double proxy_origin_reach(const Aabb& scene_bounds_WS) {
  const Vec3d lo(scene_bounds_WS.lo), hi(scene_bounds_WS.hi);
  const Vec3d extent = hi - lo;
  const double longest = std::max({extent.x, extent.y, extent.z, 0.0});
  return std::max(max_abs(lo), max_abs(hi)) + longest;
}

ProxyFrame proxy_frame_for(const Aabb& brick_bounds_WS, const Aabb& scene_bounds_WS,
                           const ProxyBuildConfig& config) {
  const Vec3d lo(brick_bounds_WS.lo), hi(brick_bounds_WS.hi);
  const Vec3d extent = hi - lo;
  const double longest = std::max({extent.x, extent.y, extent.z});
  // A brick of coinciding points still gets a positive voxel size.
  const double floor_size = std::max(std::max(max_abs(lo), max_abs(hi)) * 0x1p-30,
                                     static_cast<double>(std::numeric_limits<float>::min()));
  const double h = std::max(longest / config.resolution, floor_size);
  ProxyFrame frame;
  frame.voxel_size_WS = h;
  for (int axis = 0; axis < 3; ++axis) {
    frame.origin_WS[axis] = lo[axis] - h;
    // The box plus one voxel beyond each side, whatever the rounding.
    auto n = static_cast<int32_t>(std::ceil(extent[axis] / h)) + 2;
    while (frame.origin_WS[axis] + n * h < hi[axis] + h) ++n;
    frame.dims_IS[axis] = n;
  }
  const double wanted = 2 * proxy_rounding_bound(kWatertightHitRounding, proxy_origin_reach(scene_bounds_WS),
                                                 frame.domain_magnitude_WS());
  frame.margin_WS = std::clamp(wanted, kProxyMarginVoxels * h, kMaxProxyMarginVoxels * h);
  return frame;
}

BrickProxy build_brick_proxy(const Aabb& brick_bounds_WS, const Aabb& scene_bounds_WS,
                             std::span<const Triangle> triangles, const ProxyBuildConfig& config) {
  auto impl = std::make_unique<BrickProxy::Impl>();
  impl->frame = proxy_frame_for(brick_bounds_WS, scene_bounds_WS, config);
  const ProxyFrame& f = impl->frame;
  impl->root = std::make_unique<ProxyRoot>(false);
  ProxyRoot& root = *impl->root;

  const double h = f.voxel_size_WS, inv_h = 1.0 / h;
  const Vec3d half(0.5 * h + f.margin_WS, 0.5 * h + f.margin_WS, 0.5 * h + f.margin_WS);
  for (const Triangle& tri : triangles) {
    const Vec3d a(tri.v0), b(tri.v1), c(tri.v2);
    // Voxels whose grown box can touch the triangle's bounds.
    int32_t first[3], last[3];
    for (int axis = 0; axis < 3; ++axis) {
      const double lo = std::min({a[axis], b[axis], c[axis]}) - f.margin_WS;
      const double hi = std::max({a[axis], b[axis], c[axis]}) + f.margin_WS;
      const double i0 = std::floor((lo - f.origin_WS[axis]) * inv_h);
      const double i1 = std::floor((hi - f.origin_WS[axis]) * inv_h);
      first[axis] = static_cast<int32_t>(std::clamp(i0, 0.0, static_cast<double>(f.dims_IS[axis] - 1)));
      last[axis] = static_cast<int32_t>(std::clamp(i1, 0.0, static_cast<double>(f.dims_IS[axis] - 1)));
    }
    const bool one_voxel = first[0] == last[0] && first[1] == last[1] && first[2] == last[2];
    for (int32_t i = first[0]; i <= last[0]; ++i) {
      for (int32_t j = first[1]; j <= last[1]; ++j) {
        for (int32_t k = first[2]; k <= last[2]; ++k) {
          const openvdb::Coord voxel(i, j, k);
          const ProxyLeaf* leaf = root.probeConstLeaf(voxel);
          if (leaf != nullptr && leaf->isValueOn(voxel)) continue;
          const Vec3d centre = f.index_to_world(Vec3d(i + 0.5, j + 0.5, k + 0.5));
          if (one_voxel || triangle_overlaps_box(a, b, c, centre, half))
            root.touchLeaf(voxel)->setValueOn(voxel);
        }
      }
    }
  }
  impl->finish();
  return BrickProxy(std::move(impl));
}

}  // namespace outcore
