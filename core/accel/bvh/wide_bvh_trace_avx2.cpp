// The wide BVH's kernels on 8 AVX2 lanes. Every header this file needs is
// included before the target pragma, so only the kernel templates (and the
// lane type's functions, which carry the attribute) are compiled for AVX2:
// an inline function shared with baseline code is never emitted in an AVX2
// version the linker could pick for a CPU without it.
#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/simd_lanes.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/accel/bvh/wide_bvh_trace.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

#pragma GCC push_options
#pragma GCC target("avx2")
#include "core/accel/bvh/wide_bvh_entry_points.h"

namespace outcore::wide_avx2 {

using V = SimdLanes8;

void intersect(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
               Hit* hits) {
  wide_kernels::intersect_tree<V>(test, tree, ray_ids, rays, hits);
}

void occluded(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              uint8_t* occluded) {
  wide_kernels::occluded_tree<V>(test, tree, ray_ids, rays, occluded);
}

void all_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              std::vector<RayHitRecord>& out) {
  wide_kernels::all_hits_tree<V>(test, tree, ray_ids, rays, out);
}

void count_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                const Ray* rays, uint32_t* counts) {
  wide_kernels::count_hits_tree<V>(test, tree, ray_ids, rays, counts);
}

void set_intersect(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                   const Ray* rays, Hit* hits) {
  wide_kernels::intersect_brick_set<V>(test, set, ray_ids, rays, hits);
}

void set_occluded(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                  const Ray* rays, uint8_t* occluded) {
  wide_kernels::occluded_brick_set<V>(test, set, ray_ids, rays, occluded);
}

}  // namespace outcore::wide_avx2

#pragma GCC pop_options
