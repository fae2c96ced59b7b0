// next_bricks over the upper hierarchy collapsed to 8 children per node, the
// eight boxes of a node tested for one ray in one AVX operation: about half
// the nodes of the 4-wide walk per ray, so fewer loop trips, stack moves and
// mispredicted branches (incoherent rays on a 732-brick scene visit about
// five 4-wide nodes each). Same keys as next_bricks_wide, bitwise: each box's
// entry by the IEEE operations of slab_test4, in the same order, no FMA (the
// target is AVX, not AVX2+FMA); the binary nodes a wide node skips only prune
// what their leaves' own tests prune.
//
// The AVX code is chosen at run time (the build targets x86-64-v2): on x86,
// call it only where cpu_has_avx() (core/util/cpu_features.h) is true;
// elsewhere a scalar form gives the same keys.
//
// Thread-safety: pure functions over an immutable WideUpper8.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

#include "core/upper/upper_traversal.h"
#include "core/util/cpu_features.h"

namespace outcore {

using WideUpper8 = WideUpperOf<8>;

#if defined(__x86_64__) || defined(__i386__)
namespace detail {

// slab_test4 for the eight boxes of a node (rows of 8 floats per axis).
// Selects by and/andnot/or: GCC lowers a 256-bit blendv on a compare mask
// lane by lane under AVX (no 256-bit integer compare).
__attribute__((target("avx"))) inline uint32_t slab_test8(const SlabRay& ray, const float (&lo_rows)[3][8],
                                                          const float (&hi_rows)[3][8], float tmin,
                                                          float tmax, float min_exit, float* entry) {
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 widen = _mm256_set1_ps(kSlabWiden);
  __m256 lo = _mm256_set1_ps(tmin), hi = _mm256_set1_ps(tmax);
  for (int axis = 0; axis < 3; ++axis) {
    const __m256 o = _mm256_set1_ps(ray.origin[axis]);
    const __m256 inv = _mm256_set1_ps(ray.inverse_direction[axis]);
    const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(lo_rows[axis]), o), inv);
    const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(hi_rows[axis]), o), inv);
    const __m256 t1_nan = _mm256_cmp_ps(t1, t1, _CMP_UNORD_Q);
    const __m256 t0_where_nan = _mm256_and_ps(t1_nan, t0);
    const __m256 near = _mm256_or_ps(t0_where_nan, _mm256_andnot_ps(t1_nan, _mm256_min_ps(t0, t1)));
    const __m256 far = _mm256_or_ps(t0_where_nan, _mm256_andnot_ps(t1_nan, _mm256_max_ps(t0, t1)));
    const __m256 widened_near = _mm256_sub_ps(near, _mm256_mul_ps(_mm256_and_ps(near, abs_mask), widen));
    const __m256 widened_far = _mm256_add_ps(far, _mm256_mul_ps(_mm256_and_ps(far, abs_mask), widen));
    lo = _mm256_max_ps(widened_near, lo);
    hi = _mm256_min_ps(widened_far, hi);
  }
  _mm256_store_ps(entry, lo);
  const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(lo, hi, _CMP_LE_OQ),
                                  _mm256_cmp_ps(hi, _mm256_set1_ps(min_exit), _CMP_GE_OQ));
  return static_cast<uint32_t>(_mm256_movemask_ps(ok));
}

}  // namespace detail

// next_bricks_wide over a WideUpper8 (same arguments, same keys). Counts
// tested boxes, so its count is below the 4-wide walk's for the same ray.
template <std::size_t N>
__attribute__((target("avx"))) uint32_t next_bricks_wide8(const WideUpper8& wide, const SlabRay& ray,
                                                          float tmin, float tmax, const BrickKey& after,
                                                          std::array<BrickKey, N>& window,
                                                          uint64_t& nodes_visited) {
  uint32_t found = 0;
  if (wide.nodes.empty()) return 0;
  // Each level leaves at most seven siblings pending.
  std::array<uint32_t, 7 * kMaxUpperDepth + 8> stack;
  uint32_t top = 0;
  stack[top++] = 0;
  uint64_t visited = 0;
  while (top > 0) {
    const WideUpper8::Node& node = wide.nodes[stack[--top]];
    visited += node.count;
    // Once the window is full, only keys below its largest can enter.
    const float limit = found == N ? std::min(tmax, window[N - 1].entry) : tmax;
    alignas(32) float entry[8];
    const uint32_t mask =
        detail::slab_test8(ray, node.lo, node.hi, tmin, limit, after.entry, entry) & ((1u << node.count) - 1);
    // Inner children and leaves apart: no branch per child on its kind.
    for (uint32_t inner = mask & ~node.leaf_bits; inner != 0; inner &= inner - 1)
      stack[top++] = node.child[__builtin_ctz(inner)];
    for (uint32_t leaves = mask & node.leaf_bits; leaves != 0; leaves &= leaves - 1) {
      const uint32_t k = static_cast<uint32_t>(__builtin_ctz(leaves));
      const BrickKey key{entry[k], node.child[k]};
      if (after < key) detail::insert_key(key, window, found);
    }
  }
  nodes_visited += visited;
  return found;
}
#else
// Without AVX: box by box, by the scalar slab test (the same keys).
template <std::size_t N>
uint32_t next_bricks_wide8(const WideUpper8& wide, const SlabRay& ray, float tmin, float tmax,
                           const BrickKey& after, std::array<BrickKey, N>& window, uint64_t& nodes_visited) {
  uint32_t found = 0;
  if (wide.nodes.empty()) return 0;
  std::array<uint32_t, 7 * kMaxUpperDepth + 8> stack;
  uint32_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const WideUpper8::Node& node = wide.nodes[stack[--top]];
    nodes_visited += node.count;
    const float limit = found == N ? std::min(tmax, window[N - 1].entry) : tmax;
    for (uint32_t k = 0; k < node.count; ++k) {
      Aabb box;
      box.lo = Vec3f(node.lo[0][k], node.lo[1][k], node.lo[2][k]);
      box.hi = Vec3f(node.hi[0][k], node.hi[1][k], node.hi[2][k]);
      float entry;
      if (!detail::slab_test_scalar(ray, box, tmin, limit, after.entry, entry)) continue;
      if (!node.is_leaf[k]) {
        stack[top++] = node.child[k];
        continue;
      }
      const BrickKey key{entry, node.child[k]};
      if (after < key) detail::insert_key(key, window, found);
    }
  }
  return found;
}
#endif

}  // namespace outcore
