// TriangleHit and the contract every triangle test (mt_triangle_test.h,
// watertight_triangle_test.h, double_triangle_test.h) follows, so that the
// BVH traversal can take the test as a compile-time template parameter:
//
//   struct SomeTest {
//     static constexpr std::string_view kName;   // the --triangle-test name
//     struct Prepared { ... };                   // per-ray constants
//     static Prepared prepare(const Ray& ray);   // once per ray
//     // true when the ray hits the triangle at t with tnear < t <= tfar
//     // (Embree's segment rule; edges and vertices count as inside), writing
//     // t in units of the direction's length and Embree's barycentrics
//     // (p = (1-u-v) v0 + u v1 + v v2).
//     static bool hit(const Prepared&, const Triangle&, float tnear, float tfar, TriangleHit&);
//   };
//
// Tests see triangles that are not degenerate in float64 only (the brick
// structures leave those out, as the float64 reference never hits them).
//
// Thread-safety: plain value.
#pragma once

namespace outcore {

struct TriangleHit {
  float t;
  float u;
  float v;
};

}  // namespace outcore
