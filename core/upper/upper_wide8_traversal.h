// next_bricks over the upper hierarchy collapsed to 8 children per node, the
// eight boxes of a node tested for one ray in one AVX operation: about half
// the nodes of the 4-wide walk per ray, so fewer loop trips, stack moves and
// mispredicted branches (incoherent rays on a 732-brick scene visit about
// five 4-wide nodes each). Same keys as next_bricks_wide, bitwise: each box's
// entry by the IEEE operations of slab_test4, in the same order, no FMA (the
// target is AVX, not AVX2+FMA); the binary nodes a wide node skips only prune
// what their leaves' own tests prune.
//
// The AVX code is chosen at run time (the build targets x86-64-v2): call it
// only where cpu_has_avx() (core/util/cpu_features.h) is true.
//
// Thread-safety: pure functions over an immutable WideUpper8.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "core/upper/avx_slab.h"
#include "core/upper/upper_traversal.h"
#include "core/util/cpu_features.h"

namespace outcore {

using WideUpper8 = WideUpperOf<8>;

#if defined(__x86_64__) || defined(__i386__)
namespace detail {

// slab_test4 for the eight boxes of a node (rows of 8 floats per axis).
__attribute__((target("avx"))) inline uint32_t slab_test8(const SlabRay& ray, const float (&lo_rows)[3][8],
                                                          const float (&hi_rows)[3][8], float tmin,
                                                          float tmax, float min_exit, float* entry) {
  __m256 lo = _mm256_set1_ps(tmin), hi = _mm256_set1_ps(tmax);
  for (int axis = 0; axis < 3; ++axis) {
    const __m256 o = _mm256_set1_ps(ray.origin[axis]);
    const __m256 inv = _mm256_set1_ps(ray.inverse_direction[axis]);
    const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(lo_rows[axis]), o), inv);
    const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(hi_rows[axis]), o), inv);
    fold_slab_axis_avx(t0, t1, lo, hi);
  }
  return finish_slab_avx(lo, hi, _mm256_set1_ps(min_exit), entry);
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
// Not x86: the engine never takes the 8-wide walk there (cpu_has_avx() is
// false), so reaching this is a bug, not a user's error.
template <std::size_t N>
uint32_t next_bricks_wide8(const WideUpper8&, const SlabRay&, float, float, const BrickKey&,
                           std::array<BrickKey, N>&, uint64_t&) {
  std::fprintf(stderr, "outcore: next_bricks_wide8 called without AVX\n");
  std::abort();
}
#endif

}  // namespace outcore
