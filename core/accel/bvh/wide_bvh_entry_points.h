// The wide BVH's four entry points (closest and any hit, over one tree or a
// brick set) with the triangle test chosen by name, written once over the
// lane type and instantiated by wide_bvh_trace_sse4.cpp and
// wide_bvh_trace_avx2.cpp, each for its own V (see wide_bvh_kernels.h). The
// switch runs once per call, never per ray. Closest hits with the watertight
// test go through the packet path for camera-like runs.
//
// Thread-safety: pure functions over immutable views.
#pragma once

#include <span>

#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/wide_bvh_every_hit_kernels.h"
#include "core/accel/bvh/wide_bvh_kernels.h"
#include "core/accel/bvh/wide_bvh_packet_kernels.h"

namespace outcore::wide_kernels {

// Single-ray walks interleaved per call (wide_bvh_stepped_kernels.h): three
// for one brick's tree, reached by the queued strategy's brick visits, each
// of which starts cold in the brick; two for a brick set of one tree, which
// the chunked strategies keep warm (bunny, incoherent: two 0.98x the time
// of one, three ~1.08x).
inline constexpr int kTreeWalks = 3;
inline constexpr int kSetWalks = 2;

// Calls fn.template operator()<Lanes>() with the lane test of `test`.
template <class V, class Fn>
inline void with_lanes(TriangleTest test, Fn&& fn) {
  switch (test) {
    case TriangleTest::kMt: return fn.template operator()<MtLanes<V>>();
    case TriangleTest::kWatertight: return fn.template operator()<WatertightLanes<V>>();
    case TriangleTest::kDouble: return fn.template operator()<ScalarLanes<V, DoubleTriangleTest>>();
  }
}

template <class V>
void intersect_tree(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                    const Ray* rays, Hit* hits) {
  if (test == TriangleTest::kWatertight) {
    return intersect_watertight_coherent<V, kTreeWalks>({std::span<const WideBvhView>(&tree, 1), {}}, ray_ids,
                                                        rays, hits);
  }
  with_lanes<V>(test,
                [&]<class Lanes>() { intersect_rays<V, Lanes, kTreeWalks>(tree, ray_ids, rays, hits); });
}

template <class V>
void occluded_tree(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                   const Ray* rays, uint8_t* occluded) {
  with_lanes<V>(test,
                [&]<class Lanes>() { occluded_rays<V, Lanes, kTreeWalks>(tree, ray_ids, rays, occluded); });
}

template <class V>
void all_hits_tree(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                   const Ray* rays, std::vector<RayHitRecord>& out) {
  with_lanes<V>(test,
                [&]<class Lanes>() { all_hits_rays<V, Lanes>(tree, ray_ids, rays, RecordEveryHit<V>{out}); });
}

template <class V>
void count_hits_tree(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                     const Ray* rays, uint32_t* counts) {
  with_lanes<V>(
      test, [&]<class Lanes>() { all_hits_rays<V, Lanes>(tree, ray_ids, rays, CountEveryHit<V>{counts}); });
}

template <class V>
void intersect_brick_set(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                         const Ray* rays, Hit* hits) {
  if (test == TriangleTest::kWatertight) {
    return intersect_watertight_coherent<V, kSetWalks>(set, ray_ids, rays, hits);
  }
  with_lanes<V>(test, [&]<class Lanes>() { intersect_set<V, Lanes>(set, ray_ids, rays, hits); });
}

template <class V>
void occluded_brick_set(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                        const Ray* rays, uint8_t* occluded) {
  with_lanes<V>(test, [&]<class Lanes>() { occluded_set<V, Lanes>(set, ray_ids, rays, occluded); });
}

}  // namespace outcore::wide_kernels
