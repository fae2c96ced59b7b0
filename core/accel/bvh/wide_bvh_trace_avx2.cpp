// The wide BVH's kernels on 8 AVX2 lanes. Every header this file needs is
// included before the target pragma, so only the kernel templates (and the
// lane type's functions, which carry the attribute) are compiled for AVX2:
// an inline function shared with baseline code is never emitted in an AVX2
// version the linker could pick for a CPU without it.
#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/simd_lanes.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/accel/bvh/wide_bvh_trace.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

#pragma GCC push_options
#pragma GCC target("avx2")
#include "core/accel/bvh/wide_bvh_kernels.h"
#include "core/accel/bvh/wide_bvh_packet_kernels.h"

namespace outcore::wide_avx2 {

using V = SimdLanes8;

void intersect(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
               Hit* hits) {
  using namespace wide_kernels;
  switch (test) {
    case TriangleTest::kMt: return intersect_rays<V, MtLanes<V>>(tree, ray_ids, rays, hits);
    case TriangleTest::kWatertight:
      return intersect_watertight_coherent<V>({std::span<const WideBvhView>(&tree, 1), {}}, ray_ids, rays,
                                              hits);
    case TriangleTest::kDouble:
      return intersect_rays<V, ScalarLanes<V, DoubleTriangleTest>>(tree, ray_ids, rays, hits);
  }
}

void occluded(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              uint8_t* occluded) {
  using namespace wide_kernels;
  switch (test) {
    case TriangleTest::kMt: return occluded_rays<V, MtLanes<V>>(tree, ray_ids, rays, occluded);
    case TriangleTest::kWatertight:
      return occluded_rays<V, WatertightLanes<V>>(tree, ray_ids, rays, occluded);
    case TriangleTest::kDouble:
      return occluded_rays<V, ScalarLanes<V, DoubleTriangleTest>>(tree, ray_ids, rays, occluded);
  }
}

void set_intersect(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                   const Ray* rays, Hit* hits) {
  using namespace wide_kernels;
  switch (test) {
    case TriangleTest::kMt: return intersect_set<V, MtLanes<V>>(set, ray_ids, rays, hits);
    case TriangleTest::kWatertight: return intersect_watertight_coherent<V>(set, ray_ids, rays, hits);
    case TriangleTest::kDouble:
      return intersect_set<V, ScalarLanes<V, DoubleTriangleTest>>(set, ray_ids, rays, hits);
  }
}

void set_occluded(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                  const Ray* rays, uint8_t* occluded) {
  using namespace wide_kernels;
  switch (test) {
    case TriangleTest::kMt: return occluded_set<V, MtLanes<V>>(set, ray_ids, rays, occluded);
    case TriangleTest::kWatertight: return occluded_set<V, WatertightLanes<V>>(set, ray_ids, rays, occluded);
    case TriangleTest::kDouble:
      return occluded_set<V, ScalarLanes<V, DoubleTriangleTest>>(set, ray_ids, rays, occluded);
  }
}

}  // namespace outcore::wide_avx2

#pragma GCC pop_options
