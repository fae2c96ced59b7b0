// The wide BVH's kernels on 4 SSE lanes: the build's baseline target, for
// CPUs without AVX2 (and OUTCORE_SIMD=sse4).
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/wide_bvh_kernels.h"
#include "core/accel/bvh/wide_bvh_packet_kernels.h"
#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore::wide_sse4 {

using V = SimdLanes4;

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

}  // namespace outcore::wide_sse4
