// Traversal of a BspTreeView for one ray: the kd-tree's front-to-back walk
// (kd_detail::walk in kd_tree_traversal.h, the same code) with the planes
// of bsp_directions.h. Per ray, n . o and 1 / (n . d) are computed once for
// all 13 directions, in float64; a node's crossing is then one subtraction
// and one multiplication, as the kd-tree's.
//
// Conservative: n . o and n . d are float64 sums of at most three floats, so
// they are within 2^-52 |o|_1 and 2^-52 |d|_1 of the exact values; the
// crossing t = (s - n . o) / (n . d) is widened by
//   |t| * (kBoxMargin + 2^-22 + 2^-50 |d|_1 / |n . d|) + 2^-50 |o|_1 / |n . d|
// on both sides: the relative part is the kd-tree's margin (the triangle
// tests' own rounding of t, and the rounding of the bounds to float), the
// rest bounds the dot products' rounding with four times slack. A ray
// parallel to a plane (n . d = 0) visits the side of its origin, or both
// when its origin is within 2^-50 |o|_1 of the plane (a ray lying in a
// plane visits both with its whole segment).
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "core/accel/bsp/bsp_directions.h"
#include "core/accel/bsp/bsp_tree.h"
#include "core/accel/kdtree/kd_tree_traversal.h"

namespace outcore {
namespace bsp_detail {

inline constexpr double kRoundingMargin = 0x1p-50;

// The planes of every direction as the ray meets them.
struct DirectionPlanes {
  std::array<double, kBspDirectionCount> origin;   // n . o
  std::array<double, kBspDirectionCount> inverse;  // 1 / (n . d); unused where n . d = 0
  std::array<double, kBspDirectionCount> relative;
  std::array<double, kBspDirectionCount> absolute;
  std::array<bool, kBspDirectionCount> forward;  // n . d > 0
  std::array<bool, kBspDirectionCount> parallel;
  double parallel_margin;

  explicit DirectionPlanes(const Ray& ray) {
    const double o1 =
        std::fabs(double{ray.origin.x}) + std::fabs(double{ray.origin.y}) + std::fabs(double{ray.origin.z});
    const double d1 = std::fabs(double{ray.direction.x}) + std::fabs(double{ray.direction.y}) +
                      std::fabs(double{ray.direction.z});
    parallel_margin = kRoundingMargin * o1;
    for (uint32_t k = 0; k < kBspDirectionCount; ++k) {
      origin[k] = bsp_dot(k, ray.origin);
      const double nd = bsp_dot(k, ray.direction);
      parallel[k] = nd == 0.0;
      forward[k] = nd > 0.0;
      const double inv = parallel[k] ? 0.0 : 1.0 / nd;
      inverse[k] = inv;
      relative[k] = double{bvh_detail::kBoxMargin} + 0x1p-22 + kRoundingMargin * d1 * std::fabs(inv);
      absolute[k] = kRoundingMargin * o1 * std::fabs(inv);
    }
  }

  kd_detail::PlaneCrossing cross(const BspNode& node, float& lo, float& hi, bool& first_below) const {
    const uint32_t k = node.direction();
    const double split = node.split();
    if (parallel[k]) {
      first_below = true;
      if (origin[k] < split - parallel_margin) return kd_detail::PlaneCrossing::kBelowOnly;
      if (origin[k] > split + parallel_margin) return kd_detail::PlaneCrossing::kAboveOnly;
      return kd_detail::PlaneCrossing::kInPlane;
    }
    first_below = forward[k];
    const double t = (split - origin[k]) * inverse[k];
    const double margin = std::fabs(t) * relative[k] + absolute[k];
    lo = static_cast<float>(t - margin);
    hi = static_cast<float>(t + margin);
    return kd_detail::PlaneCrossing::kCrosses;
  }
};

// Calls leaf(first, count, limit) for the leaves the segment [tmin, limit]
// may touch, front to back (as kd_detail::traverse).
template <class Leaf>
inline void traverse(const BspTreeView& tree, const Ray& ray, float tmin, float& limit, Leaf&& leaf) {
  if (tree.nodes.empty()) return;
  const bvh_detail::BoxRay box_ray(ray);
  float segment_min, segment_max;
  if (!kd_detail::clip_to_bounds(tree.bounds, ray, box_ray, tmin, limit, segment_min, segment_max)) return;
  const DirectionPlanes planes(ray);
  kd_detail::walk<kMaxBspDepth>(tree.nodes.data(), planes, segment_min, segment_max, limit, leaf);
}

}  // namespace bsp_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test>
bool bsp_closest_hit(const BspTreeView& tree, const Ray& ray, Hit& best) {
  return kd_detail::closest_hit<Test>(tree, ray, best, [&](float tmin, float& limit, auto&& leaf) {
    bsp_detail::traverse(tree, ray, tmin, limit, leaf);
  });
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test>
bool bsp_any_hit(const BspTreeView& tree, const Ray& ray) {
  return kd_detail::any_hit<Test>(tree, ray, [&](float tmin, float& limit, auto&& leaf) {
    bsp_detail::traverse(tree, ray, tmin, limit, leaf);
  });
}

}  // namespace outcore
