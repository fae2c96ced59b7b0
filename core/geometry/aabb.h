// Aabb: axis-aligned bounding box in float, the unit of every spatial decision
// (brick bounds, upper-hierarchy nodes, SAH costs). An empty box has lo > hi.
//
// Thread-safety: plain value.
#pragma once

#include <limits>

#include "core/geometry/vec3.h"

namespace outcore {

struct Aabb {
  Vec3f lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
           std::numeric_limits<float>::infinity()};
  Vec3f hi{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
           -std::numeric_limits<float>::infinity()};

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void extend(const Vec3f& p) {
    lo = min(lo, p);
    hi = max(hi, p);
  }
  void extend(const Aabb& b) {
    lo = min(lo, b.lo);
    hi = max(hi, b.hi);
  }
  Vec3f extent() const { return hi - lo; }
  Vec3f center() const { return (lo + hi) * 0.5f; }
  bool contains(const Vec3f& p) const {
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
  }
  bool contains(const Aabb& b) const { return contains(b.lo) && contains(b.hi); }
  // Half the surface area: the SAH only compares areas, so the factor 2 is dropped.
  double half_area() const {
    if (empty()) return 0.0;
    const Vec3d e(extent());
    return e.x * e.y + e.y * e.z + e.z * e.x;
  }
  int largest_axis() const {
    const Vec3f e = extent();
    return (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
  }
  bool operator==(const Aabb&) const = default;
};

}  // namespace outcore
