// The AVX form of the slab test's arithmetic, shared by the 8-wide walk (one
// ray, eight boxes) and the packet walk (eight rays, one box): per lane the
// IEEE operations of detail::slab_test4 in the same order, so entries are
// bitwise the SSE and scalar tests' (upper_traversal.h). x86 only; the
// callers are themselves compiled for AVX and chosen at run time.
//
// Thread-safety: pure functions.
#pragma once

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>

#include "core/upper/upper_traversal.h"

namespace outcore::detail {

// Folds one axis into [lo, hi]: t0 and t1 are the distances to the axis's
// two slab planes, (plane - origin) * inverse direction.
__attribute__((target("avx"))) inline void fold_slab_axis_avx(__m256 t0, __m256 t1, __m256& lo, __m256& hi) {
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 widen = _mm256_set1_ps(kSlabWiden);
  // As in slab_test4: minps / maxps give their second operand when either is
  // NaN, right for a NaN t0; a NaN t1 gives t0. Selects by and/andnot/or,
  // not blendv: GCC lowers a 256-bit blendv on a compare mask through
  // integer compares AVX lacks, lane by lane with a branch each.
  const __m256 t1_nan = _mm256_cmp_ps(t1, t1, _CMP_UNORD_Q);
  const __m256 t0_where_nan = _mm256_and_ps(t1_nan, t0);
  const __m256 near = _mm256_or_ps(t0_where_nan, _mm256_andnot_ps(t1_nan, _mm256_min_ps(t0, t1)));
  const __m256 far = _mm256_or_ps(t0_where_nan, _mm256_andnot_ps(t1_nan, _mm256_max_ps(t0, t1)));
  const __m256 widened_near = _mm256_sub_ps(near, _mm256_mul_ps(_mm256_and_ps(near, abs_mask), widen));
  const __m256 widened_far = _mm256_add_ps(far, _mm256_mul_ps(_mm256_and_ps(far, abs_mask), widen));
  lo = _mm256_max_ps(widened_near, lo);  // widened_near > lo ? widened_near : lo
  hi = _mm256_min_ps(widened_far, hi);   // widened_far < hi ? widened_far : hi
}

// Stores the entries and returns the mask of the lanes that pass:
// lo <= hi and hi >= min_exit.
__attribute__((target("avx"))) inline uint32_t finish_slab_avx(__m256 lo, __m256 hi, __m256 min_exit,
                                                               float* entry) {
  _mm256_storeu_ps(entry, lo);
  const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(lo, hi, _CMP_LE_OQ), _mm256_cmp_ps(hi, min_exit, _CMP_GE_OQ));
  return static_cast<uint32_t>(_mm256_movemask_ps(ok));
}

}  // namespace outcore::detail
#endif
