// watertight_lanes: the watertight test's float part (Woop, Benthin, Wald
// 2013; watertight_triangle_test.h) on the lanes of a lane type V
// (simd_lanes.h), each lane with the scalar test's IEEE operations in the
// scalar order, so that a lane's t, v, w and det are bitwise the scalar
// test's. One triangle against many rays (the wide BVH's packets) and many
// triangles against one ray (the wide BVH's leaves, the split-plane trees'
// and the grids' references, watertight_ref_lanes.h) both use it.
// wide_bvh_trace_avx2.cpp must reach it after its target pragma (through
// wide_bvh_kernels.h), so that its SimdLanes8 instances are AVX2 code.
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>

#include "core/accel/bvh/simd_lanes.h"
#include "core/accel/bvh/triangle_hit.h"
#include "core/accel/bvh/watertight_triangle_test.h"

#if defined(__x86_64__) || defined(__i386__)
namespace outcore::wide_kernels {

// A ray's prepared watertight inputs (WatertightTriangleTest::prepare), the
// permuted origin and the shear broadcast to every lane.
template <class V>
struct WatertightRayLanes {
  WatertightTriangleTest::Axes axes{};
  typename V::F origin[3], shear[3];

  void set(const WatertightTriangleTest::Prepared& p) {
    axes = {p.kx, p.ky, p.kz};
    origin[0] = V::set1(p.ox);
    origin[1] = V::set1(p.oy);
    origin[2] = V::set1(p.oz);
    shear[0] = V::set1(p.sx);
    shear[1] = V::set1(p.sy);
    shear[2] = V::set1(p.sz);
  }
};

// Where watertight_lanes() leaves the lanes that pass.
template <class V>
struct WatertightLaneHits {
  alignas(32) float t[V::kWidth], v[V::kWidth], w[V::kWidth], det[V::kWidth];

  // A passing lane's hit: t and the barycentrics as the scalar test
  // finishes them (watertight_triangle_test.h).
  TriangleHit hit(uint32_t lane) const {
    const float inv = 1.0f / det[lane];
    return {t[lane], v[lane] * inv, w[lane] * inv};
  }
};

// The watertight test's float part (watertight_triangle_test.h) on V::kWidth
// lanes, each lane with the scalar operations in the scalar order:
// vertex(v, axis) gives vertex v's coordinate on that axis for every lane,
// origin and shear are the permuted origin (x, y across the ray, z along
// it) and shear per lane. An edge function that is 0 in float is redone,
// with its two neighbours, in double, where the products are exact. Stores
// t, v, w, det of the lanes of `lanes` that pass the edge signs, det != 0 and
// tnear < t <= tfar in `out`; returns their mask. One triangle against many
// rays (packets) and many triangles against one ray both use it.
template <class V, class Vertex>
inline uint32_t watertight_lanes(Vertex&& vertex, const WatertightTriangleTest::Axes& k,
                                 const typename V::F (&origin)[3], const typename V::F (&shear)[3],
                                 uint32_t lanes, typename V::F tnear, typename V::F tfar,
                                 WatertightLaneHits<V>& out) {
  using F = typename V::F;
  const F &ox = origin[0], &oy = origin[1], &oz = origin[2];
  const F &sx = shear[0], &sy = shear[1], &sz = shear[2];
  const F az = V::sub(vertex(0, k.kz), oz), bz = V::sub(vertex(1, k.kz), oz),
          cz = V::sub(vertex(2, k.kz), oz);
  const F ax = V::sub(V::sub(vertex(0, k.kx), ox), V::mul(sx, az));
  const F ay = V::sub(V::sub(vertex(0, k.ky), oy), V::mul(sy, az));
  const F bx = V::sub(V::sub(vertex(1, k.kx), ox), V::mul(sx, bz));
  const F by = V::sub(V::sub(vertex(1, k.ky), oy), V::mul(sy, bz));
  const F cx = V::sub(V::sub(vertex(2, k.kx), ox), V::mul(sx, cz));
  const F cy = V::sub(V::sub(vertex(2, k.ky), oy), V::mul(sy, cz));
  F u = V::sub(V::mul(cx, by), V::mul(cy, bx));
  F v = V::sub(V::mul(ax, cy), V::mul(ay, cx));
  F w = V::sub(V::mul(bx, ay), V::mul(by, ax));
  const F zero = V::set1(0.0f);
  const uint32_t on_edge =
      lanes & V::mask(V::bit_or(V::bit_or(V::eq(u, zero), V::eq(v, zero)), V::eq(w, zero)));
  if (on_edge != 0) {
    float parts[9][V::kWidth];
    const F values[9] = {ax, ay, bx, by, cx, cy, u, v, w};
    for (int p = 0; p < 9; ++p) V::store(parts[p], values[p]);
    for (uint32_t bits = on_edge; bits != 0; bits &= bits - 1) {
      const int i = __builtin_ctz(bits);
      const double dax = parts[0][i], day = parts[1][i], dbx = parts[2][i], dby = parts[3][i];
      const double dcx = parts[4][i], dcy = parts[5][i];
      parts[6][i] = static_cast<float>(dcx * dby - dcy * dbx);
      parts[7][i] = static_cast<float>(dax * dcy - day * dcx);
      parts[8][i] = static_cast<float>(dbx * day - dby * dax);
    }
    u = V::load_unaligned(parts[6]);
    v = V::load_unaligned(parts[7]);
    w = V::load_unaligned(parts[8]);
  }
  const F negative = V::bit_or(V::bit_or(V::lt(u, zero), V::lt(v, zero)), V::lt(w, zero));
  const F positive = V::bit_or(V::bit_or(V::gt(u, zero), V::gt(v, zero)), V::gt(w, zero));
  uint32_t pass = lanes & ~(V::mask(negative) & V::mask(positive));
  if (pass == 0) return 0;
  const F det = V::add(V::add(u, v), w);
  const F t = V::div(
      V::add(V::add(V::mul(u, V::mul(sz, az)), V::mul(v, V::mul(sz, bz))), V::mul(w, V::mul(sz, cz))), det);
  pass &= V::mask(V::bit_and(V::bit_and(V::neq(det, zero), V::gt(t, tnear)), V::le(t, tfar)));
  if (pass != 0) {
    V::store(out.t, t);
    V::store(out.v, v);
    V::store(out.w, w);
    V::store(out.det, det);
  }
  return pass;
}

}  // namespace outcore::wide_kernels
#endif
