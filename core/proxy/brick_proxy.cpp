#include "core/proxy/brick_proxy.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/proxy/proxy_grid.h"

namespace outcore {

namespace {

// See brick_proxy.h: the segment is widened by this much of its ends (the t of
// a grazing hit is less accurate than its position) ...
constexpr double kSegmentWiden = 0x1p-8;
// ... and by the rounding bound E = proxy_rounding_bound(scale, |origin|, |brick|).

// True when an occupied voxel lies on the index-space segment [t0, t1] of
// `ray`, which runs inside one 8^3 block (up to rounding: coordinates that
// round into a neighbouring block are looked up there).
bool block_touched(const ProxyRayIS& ray, double t0, double t1, ProxyLeafCache& leaves) {
  openvdb::math::DDA<ProxyRayIS, 0> voxels(ray, t0, t1);
  do {
    if (leaves.is_on(voxels.voxel())) return true;
  } while (voxels.step());
  return false;
}

}  // namespace

double ProxyFrame::domain_magnitude_WS() const {
  double magnitude = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const double lo = origin_WS[axis];
    const double hi = lo + dims_IS[axis] * voxel_size_WS;
    magnitude = std::max({magnitude, std::fabs(lo), std::fabs(hi)});
  }
  return magnitude;
}

void BrickProxy::Impl::finish() {
  inverse_voxel_size_WS = 1.0 / frame.voxel_size_WS;
  domain_magnitude_WS = frame.domain_magnitude_WS();
  if (root) active_voxels = root->onVoxelCount();
}

BrickProxy::BrickProxy() = default;
BrickProxy::BrickProxy(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BrickProxy::~BrickProxy() = default;
BrickProxy::BrickProxy(BrickProxy&&) noexcept = default;
BrickProxy& BrickProxy::operator=(BrickProxy&&) noexcept = default;

const ProxyFrame& BrickProxy::frame() const {
  static const ProxyFrame kEmpty;
  return impl_ ? impl_->frame : kEmpty;
}

uint64_t BrickProxy::active_voxels() const {
  return impl_ ? impl_->active_voxels : 0;
}

uint64_t BrickProxy::memory_bytes() const {
  if (!impl_) return 0;
  uint64_t bytes = sizeof(Impl);
  if (impl_->root) bytes += impl_->root->memUsage();
  return bytes;
}

bool BrickProxy::is_occupied(int32_t i, int32_t j, int32_t k) const {
  if (!impl_ || !impl_->root) return false;
  ProxyLeafCache leaves(*impl_->root);
  return leaves.is_on(openvdb::Coord(i, j, k));
}

bool BrickProxy::may_hit(const Ray& ray, float tmin_f, float tmax_f, double rounding_scale) const {
  if (!impl_ || !impl_->root) return true;  // no proxy: cannot decide
  const Impl& p = *impl_;
  const ProxyFrame& f = p.frame;
  const Vec3d o(ray.origin), d(ray.direction);

  // The rounding bound; beyond half the builder's margin the grid cannot decide.
  const double rounding = proxy_rounding_bound(rounding_scale, max_abs(o), p.domain_magnitude_WS);
  if (!(2 * rounding <= f.margin_WS)) return true;

  // The segment, widened, then clipped to the grid's domain (which extends a
  // voxel beyond the brick's box on every side) in world space.
  const double scale = length(d);
  const double slack_t = rounding / scale;
  const double tmin = static_cast<double>(tmin_f);
  const double tmax = static_cast<double>(tmax_f);
  double t0 = tmin - (std::fabs(tmin) * kSegmentWiden + slack_t);
  double t1 = tmax + (std::fabs(tmax) * kSegmentWiden + slack_t);
  for (int axis = 0; axis < 3; ++axis) {
    const double lo = f.origin_WS[axis];
    const double hi = lo + f.dims_IS[axis] * f.voxel_size_WS;
    if (d[axis] == 0.0) {
      if (o[axis] < lo || o[axis] > hi) return false;
      continue;
    }
    const double inv = 1.0 / d[axis];
    double near = (lo - o[axis]) * inv, far = (hi - o[axis]) * inv;
    if (near > far) std::swap(near, far);
    t0 = std::max(t0, near);
    t1 = std::min(t1, far);
  }
  if (!(t0 <= t1)) return false;

  // Index space: same parameter t.
  const double inv_h = p.inverse_voxel_size_WS;
  using Vec3IS = ProxyRayIS::Vec3T;
  const ProxyRayIS ray_IS(
      Vec3IS((o.x - f.origin_WS.x) * inv_h, (o.y - f.origin_WS.y) * inv_h, (o.z - f.origin_WS.z) * inv_h),
      Vec3IS(d.x * inv_h, d.y * inv_h, d.z * inv_h), t0, t1);
  ProxyLeafCache leaves(*p.root);
  // Hierarchical: 8^3 leaf blocks first, voxels only inside present leaves
  // (the tree has no tiles: neither the builder nor the reader makes any).
  openvdb::math::DDA<ProxyRayIS, ProxyLeaf::TOTAL> blocks(ray_IS, t0, t1);
  do {
    if (leaves.leaf(blocks.voxel()) != nullptr &&
        block_touched(ray_IS, blocks.time(), blocks.next(), leaves)) {
      return true;
    }
  } while (blocks.step());
  return false;
}

}  // namespace outcore
