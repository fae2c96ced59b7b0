// How far the exact ray may pass from a triangle that a float ray/triangle
// test accepts, as a fraction of |ray origin|inf + |coordinates near the
// triangle|inf. Brick structures report theirs
// (BrickBuilder::hit_rounding_scale()); the brick proxies widen their test by
// it (core/proxy/brick_proxy.h explains both values and their limits;
// core/proxy/proxy_rounding_test.cpp measures them).
//
// Thread-safety: constants only.
#pragma once

namespace outcore {

// Watertight (Woop et al. 2013) and float64 tests: 16 float epsilons.
inline constexpr double kWatertightHitRounding = 0x1p-19;
// Moeller-Trumbore tests (Embree's, bvh's mt): 256 float epsilons, which
// bounds their non-grazing acceptances only.
inline constexpr double kMollerTrumboreHitRounding = 0x1p-15;

}  // namespace outcore
