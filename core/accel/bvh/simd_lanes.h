// SimdLanes4 (SSE, the build's x86-64-v2 baseline) and SimdLanes8 (AVX2,
// chosen at run time): the few float operations the wide BVH's kernels
// (wide_bvh_kernels.h) are written in, so that one template serves both
// widths. Every operation is the single IEEE operation of its name — no fused
// multiply-add — so a lane computes bitwise what the scalar code computes
// with the same expression.
//
// min/max keep the SSE rule: when either operand is NaN the result is the
// second operand; the box test relies on it.
//
// SimdLanes8's functions carry the avx2 target; call them only from code
// compiled for it (wide_bvh_trace_avx2.cpp) on a CPU that has it.
//
// Thread-safety: pure functions.
#pragma once

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>

#include <cstdint>

namespace outcore {

struct SimdLanes4 {
  using F = __m128;
  static constexpr uint32_t kWidth = 4;
  static F load(const float* p) { return _mm_load_ps(p); }  // 16-byte aligned
  static F load_unaligned(const float* p) { return _mm_loadu_ps(p); }
  static void store(float* p, F a) { _mm_storeu_ps(p, a); }
  static F set1(float x) { return _mm_set1_ps(x); }
  static F add(F a, F b) { return _mm_add_ps(a, b); }
  static F sub(F a, F b) { return _mm_sub_ps(a, b); }
  static F mul(F a, F b) { return _mm_mul_ps(a, b); }
  static F div(F a, F b) { return _mm_div_ps(a, b); }
  static F min(F a, F b) { return _mm_min_ps(a, b); }
  static F max(F a, F b) { return _mm_max_ps(a, b); }
  static F bit_and(F a, F b) { return _mm_and_ps(a, b); }
  static F blend(F a, F b, F mask) { return _mm_blendv_ps(a, b, mask); }  // mask ? b : a
  static F bit_or(F a, F b) { return _mm_or_ps(a, b); }
  static F lt(F a, F b) { return _mm_cmplt_ps(a, b); }
  static F le(F a, F b) { return _mm_cmple_ps(a, b); }
  static F gt(F a, F b) { return _mm_cmpgt_ps(a, b); }
  static F ge(F a, F b) { return _mm_cmpge_ps(a, b); }
  static F eq(F a, F b) { return _mm_cmpeq_ps(a, b); }
  static F neq(F a, F b) { return _mm_cmpneq_ps(a, b); }  // true for NaN, as scalar !=
  static uint32_t mask(F a) { return static_cast<uint32_t>(_mm_movemask_ps(a)); }
};

#define OUTCORE_AVX2 __attribute__((target("avx2"), always_inline)) static inline

struct SimdLanes8 {
  using F = __m256;
  static constexpr uint32_t kWidth = 8;
  OUTCORE_AVX2 F load(const float* p) { return _mm256_load_ps(p); }  // 32-byte aligned
  OUTCORE_AVX2 F load_unaligned(const float* p) { return _mm256_loadu_ps(p); }
  OUTCORE_AVX2 void store(float* p, F a) { _mm256_storeu_ps(p, a); }
  OUTCORE_AVX2 F set1(float x) { return _mm256_set1_ps(x); }
  OUTCORE_AVX2 F add(F a, F b) { return _mm256_add_ps(a, b); }
  OUTCORE_AVX2 F sub(F a, F b) { return _mm256_sub_ps(a, b); }
  OUTCORE_AVX2 F mul(F a, F b) { return _mm256_mul_ps(a, b); }
  OUTCORE_AVX2 F div(F a, F b) { return _mm256_div_ps(a, b); }
  OUTCORE_AVX2 F min(F a, F b) { return _mm256_min_ps(a, b); }
  OUTCORE_AVX2 F max(F a, F b) { return _mm256_max_ps(a, b); }
  OUTCORE_AVX2 F bit_and(F a, F b) { return _mm256_and_ps(a, b); }
  OUTCORE_AVX2 F blend(F a, F b, F mask) { return _mm256_blendv_ps(a, b, mask); }  // mask ? b : a
  OUTCORE_AVX2 F bit_or(F a, F b) { return _mm256_or_ps(a, b); }
  OUTCORE_AVX2 F lt(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
  OUTCORE_AVX2 F le(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
  OUTCORE_AVX2 F gt(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
  OUTCORE_AVX2 F ge(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
  OUTCORE_AVX2 F eq(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_EQ_OQ); }
  OUTCORE_AVX2 F neq(F a, F b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
  OUTCORE_AVX2 uint32_t mask(F a) { return static_cast<uint32_t>(_mm256_movemask_ps(a)); }
};

#undef OUTCORE_AVX2

}  // namespace outcore
#endif
