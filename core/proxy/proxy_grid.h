// ProxyGrid: the OpenVDB tree behind a brick's occupancy proxy, and
// BrickProxy::Impl, which owns one. Internal to core/proxy: only its .cpp
// files include this header, so OpenVDB stays out of the engine's headers.
//
// The tree is OpenVDB's mask tree, root -> one internal level of 8^3
// children -> 8^3-voxel ValueMask leaves (64 B of bits each), used through
// OpenVDB's node templates and math::DDA, which are header-only:
//   - not openvdb::MaskGrid (Tree4<ValueMask, 5, 4, 3>): a proxy spans a few
//     dozen voxels per axis, and the standard configuration's 32^3 and 16^3
//     internal nodes alone cost about 290 KiB per grid (their child tables),
//     against about 4 KiB for the 8^3 internal node here;
//   - not openvdb::Grid / tree::Tree / ValueAccessor either: those pull in
//     libopenvdb.so, whose load-time (BIND_NOW) relocation through its 22 MB
//     symbol string table adds 25-30 MiB to the RSS of every outcore
//     process, `pack` included (measured; it broke the packer's memory
//     bound). The one-leaf cache below does what ValueAccessor's leaf level
//     does.
//
// Index space (...IS): voxel (i, j, k) covers [i, i+1) x [j, j+1) x [k, k+1),
// which is what openvdb::math::DDA steps through (Coord::floor of a point).
// World space (...WS): p_WS = origin_WS + p_IS * voxel_size_WS, kept in
// float64 in the ProxyFrame.
//
// Thread-safety: a tree is immutable once built and may then be read from any
// number of threads, each through its own ProxyLeafCache.
#pragma once

#include <openvdb/math/DDA.h>
#include <openvdb/tree/InternalNode.h>
#include <openvdb/tree/LeafNode.h>
#include <openvdb/tree/RootNode.h>

#include <memory>

#include "core/proxy/brick_proxy.h"

namespace outcore {

using ProxyLeaf = openvdb::tree::LeafNode<openvdb::ValueMask, 3>;
using ProxyInternal = openvdb::tree::InternalNode<ProxyLeaf, 3>;
using ProxyRoot = openvdb::tree::RootNode<ProxyInternal>;

// A ray in index space, as openvdb::math::DDA wants it (what math::Ray
// offers, without math::Ray's Transform.h, which needs libopenvdb.so).
struct ProxyRayIS {
  using RealType = double;
  using Vec3Type = openvdb::math::Vec3<double>;
  using Vec3T = Vec3Type;

  ProxyRayIS(const Vec3T& eye, const Vec3T& dir, double t0, double t1)
      : eye_(eye), dir_(dir), inv_dir_(1.0 / dir[0], 1.0 / dir[1], 1.0 / dir[2]), t0_(t0), t1_(t1) {}
  Vec3T operator()(double t) const { return eye_ + dir_ * t; }
  const Vec3T& dir() const { return dir_; }
  const Vec3T& invDir() const { return inv_dir_; }
  double t0() const { return t0_; }
  double t1() const { return t1_; }

 private:
  Vec3T eye_, dir_, inv_dir_;
  double t0_, t1_;
};

// Read access with the last leaf cached (one per thread or call).
class ProxyLeafCache {
 public:
  explicit ProxyLeafCache(const ProxyRoot& root) : root_(root) {}
  // The leaf holding xyz, or nullptr (an empty 8^3 block).
  const ProxyLeaf* leaf(const openvdb::Coord& xyz) {
    const openvdb::Coord key = xyz & ~(ProxyLeaf::DIM - 1);
    if (key != key_) {
      key_ = key;
      leaf_ = root_.probeConstLeaf(key);
    }
    return leaf_;
  }
  bool is_on(const openvdb::Coord& xyz) {
    const ProxyLeaf* l = leaf(xyz);
    return l != nullptr && l->isValueOn(xyz);
  }

 private:
  const ProxyRoot& root_;
  openvdb::Coord key_{1, 1, 1};  // never a leaf origin
  const ProxyLeaf* leaf_ = nullptr;
};

struct BrickProxy::Impl {
  ProxyFrame frame;
  std::unique_ptr<ProxyRoot> root;
  uint64_t active_voxels = 0;
  // Largest |coordinate| of the grid's domain: the scale of the float rounding
  // in a ray/triangle test near this brick (brick_proxy.cpp).
  double domain_magnitude_WS = 0;
  double inverse_voxel_size_WS = 0;

  // Sets the derived fields from `frame` and the tree.
  void finish();
};

}  // namespace outcore
