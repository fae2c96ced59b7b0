// bound_segment_overlaps: whether a bound's float64 interval of ray
// parameters [enter, leave] meets a ray's segment [tmin, tmax] widened by
// 2^-8 of its ends, the widening the brick proxies use so that a hit a float
// test reports at t <= tmax, whose exact point may lie a little beyond (a
// grazing ray's t is far less accurate than its position), is never cut off.
// Shared by the brick bounds (bounding_sphere.h, oriented_box.h).
//
// Thread-safety: a pure function.
#pragma once

#include <algorithm>
#include <cmath>

namespace outcore {

inline bool bound_segment_overlaps(double enter, double leave, float tmin, float tmax) {
  constexpr double kWiden = 0x1p-8;
  const double lo = static_cast<double>(tmin) - kWiden * std::fabs(static_cast<double>(tmin));
  const double hi = static_cast<double>(tmax) + kWiden * std::fabs(static_cast<double>(tmax));
  return enter <= hi && leave >= lo && enter <= leave;
}

}  // namespace outcore
