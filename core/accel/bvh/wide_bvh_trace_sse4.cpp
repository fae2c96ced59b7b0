// The wide BVH's entry points on 4 SSE lanes: the build's baseline target,
// for CPUs without AVX2 (and OUTCORE_SIMD=sse4).
#include "core/accel/bvh/wide_bvh_entry_points.h"
#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore::wide_sse4 {

using V = SimdLanes4;

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

}  // namespace outcore::wide_sse4
