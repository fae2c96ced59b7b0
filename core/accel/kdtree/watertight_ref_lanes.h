// The watertight test of a leaf's (or a cell's) triangle references four at
// a time, for the structures that keep a brick's triangles in input order
// and leaves as runs of references (the kd-tree, the BSP, the grids, the
// octree, the quadtree; kd_tree_traversal.h's closest_hit and any_hit). The
// references the mailbox admits are gathered into rows and tested on SSE's
// four lanes by watertight_lanes (the build's x86-64-v2 baseline, no
// dispatch), each lane with the scalar test's operations in its order, so
// t, u, v are bitwise WatertightTriangleTest::hit's; the in-plane check runs
// per passing lane, as in the scalar test. Measured against one reference
// at a time: docs/BENCHMARKS.md, issue 24.
//
// Thread-safety: one object per ray walk.
#pragma once

#include <cstdint>

#include "core/accel/bvh/triangle_hit.h"
#include "core/accel/bvh/watertight_lanes.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/geometry/triangle.h"

#if defined(__x86_64__) || defined(__i386__)
namespace outcore::kd_detail {

class WatertightRefLanes {
 public:
  using V = SimdLanes4;
  static constexpr uint32_t kLanes = V::kWidth;

  explicit WatertightRefLanes(const WatertightTriangleTest::Prepared& ray) : direction_(ray.direction) {
    ray_lanes_.set(ray);
  }

  // Tests triangles[refs[k]] for k < count that mailbox.first_visit admits
  // over (tnear, tfar], calling on_hit(triangle, hit) for each hit; on_hit
  // may lower tfar (read again for every four) and returns true to stop,
  // which test() then returns.
  template <class Mailbox, class OnHit>
  bool test(const uint32_t* refs, uint32_t count, const Triangle* triangles, Mailbox& mailbox, float tnear,
            const float& tfar, OnHit&& on_hit) {
    uint32_t gathered = 0;
    for (uint32_t k = 0; k < count; ++k) {
      const uint32_t tri = refs[k];
      if (!mailbox.first_visit(tri)) continue;
      gather(triangles[tri], gathered);
      ids_[gathered++] = tri;
      if (gathered == kLanes) {
        if (test_gathered(gathered, triangles, tnear, tfar, on_hit)) return true;
        gathered = 0;
      }
    }
    return gathered != 0 && test_gathered(gathered, triangles, tnear, tfar, on_hit);
  }

 private:
  void gather(const Triangle& tri, uint32_t lane) {
    const Vec3f* vertices[3] = {&tri.v0, &tri.v1, &tri.v2};
    for (int v = 0; v < 3; ++v) {
      for (int axis = 0; axis < 3; ++axis) rows_[3 * v + axis][lane] = (*vertices[v])[axis];
    }
  }

  template <class OnHit>
  bool test_gathered(uint32_t gathered, const Triangle* triangles, float tnear, const float& tfar,
                     OnHit&& on_hit) {
    // Lanes past the gathered ones repeat the first: computed, never reported.
    for (uint32_t lane = gathered; lane < kLanes; ++lane) {
      for (auto& row : rows_) row[lane] = row[0];
    }
    const auto vertex = [&](int v, int axis) { return V::load(rows_[3 * v + axis]); };
    const uint32_t pass =
        wide_kernels::watertight_lanes<V>(vertex, ray_lanes_.axes, ray_lanes_.origin, ray_lanes_.shear,
                                          (1u << gathered) - 1u, V::set1(tnear), V::set1(tfar), found_);
    for (uint32_t bits = pass; bits != 0; bits &= bits - 1) {
      const auto lane = static_cast<uint32_t>(__builtin_ctz(bits));
      const uint32_t tri = ids_[lane];
      if (WatertightTriangleTest::in_plane(direction_, triangles[tri])) continue;
      if (on_hit(tri, found_.hit(lane))) return true;
    }
    return false;
  }

  wide_kernels::WatertightRayLanes<V> ray_lanes_;
  Vec3f direction_;
  alignas(16) float rows_[9][kLanes];
  uint32_t ids_[kLanes];
  wide_kernels::WatertightLaneHits<V> found_;
};

}  // namespace outcore::kd_detail
#endif
