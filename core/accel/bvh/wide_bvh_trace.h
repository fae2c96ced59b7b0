// Tracing rays through a WideBvhView (wide_bvh.h): closest hit and any hit
// for a list of rays, with the triangle test chosen by name, on the SIMD path
// chosen once per process — AVX2 (8 lanes) where the CPU has it, SSE (4
// lanes, the build's x86-64-v2 baseline) otherwise. OUTCORE_SIMD=sse4 forces
// the SSE path (tests and benchmarks compare the two); OUTCORE_SIMD=avx2 on a
// CPU without AVX2 is refused at start (simd_path_from_environment).
//
// Answers are bitwise the same on both paths and equal to the binary tree's
// scalar traversal (bvh_traversal.h) with the same test.
//
// Thread-safety: pure functions over an immutable view; any thread.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "core/accel/brick_queries.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"
#include "core/util/status.h"

namespace outcore {

enum class SimdPath { kSse4, kAvx2 };

std::string_view simd_path_name(SimdPath path);
// Whether this CPU can run the path.
bool simd_path_supported(SimdPath path);
// The path OUTCORE_SIMD names (sse4 or avx2), else the widest this CPU
// runs. INVALID_ARGUMENT for another name or an unsupported path.
Expected<SimdPath> simd_path_from_environment();
// The process's path: simd_path_from_environment() decided once; an invalid
// OUTCORE_SIMD falls back to the widest path (the CLI reports the error at
// start, see check_simd_environment in the engine options).
SimdPath active_simd_path();

// For each i in ray_ids: closest hit over [tnear, min(tfar, hits[i].t)],
// replacing hits[i] when hit_is_better says so.
void wide_bvh_intersect(SimdPath path, TriangleTest test, const WideBvhView& tree,
                        std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits);
// For each i in ray_ids with occluded[i] == 0: 1 when the ray hits anything.
void wide_bvh_occluded(SimdPath path, TriangleTest test, const WideBvhView& tree,
                       std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded);

// Every hit of each ray in (tnear, tfar], appended to `out` ray by ray
// (brick_queries.h).
void wide_bvh_all_hits(SimdPath path, TriangleTest test, const WideBvhView& tree,
                       std::span<const uint32_t> ray_ids, const Ray* rays, std::vector<RayHitRecord>& out);
// Adds each ray's hits in (tnear, tfar] to counts[i] (no records).
void wide_bvh_count_hits(SimdPath path, TriangleTest test, const WideBvhView& tree,
                         std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts);
// Appends one record: the every-hit kernels call it, so that no std::vector
// code is compiled inside the SIMD-targeted files (wide_bvh_trace_avx2.cpp).
void append_hit(std::vector<RayHitRecord>& out, uint32_t ray, const Hit& hit);

// The same over a set of trees, as if they were one.
void wide_bvh_set_intersect(SimdPath path, TriangleTest test, const WideBvhSetView& set,
                            std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits);
void wide_bvh_set_occluded(SimdPath path, TriangleTest test, const WideBvhSetView& set,
                           std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded);

namespace wide_sse4 {
void intersect(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
               Hit* hits);
void all_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              std::vector<RayHitRecord>& out);
void count_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                const Ray* rays, uint32_t* counts);
void occluded(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              uint8_t* occluded);
void set_intersect(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                   const Ray* rays, Hit* hits);
void set_occluded(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                  const Ray* rays, uint8_t* occluded);
}  // namespace wide_sse4
namespace wide_avx2 {
void intersect(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
               Hit* hits);
void all_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              std::vector<RayHitRecord>& out);
void count_hits(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids,
                const Ray* rays, uint32_t* counts);
void occluded(TriangleTest test, const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
              uint8_t* occluded);
void set_intersect(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                   const Ray* rays, Hit* hits);
void set_occluded(TriangleTest test, const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                  const Ray* rays, uint8_t* occluded);
}  // namespace wide_avx2

}  // namespace outcore
