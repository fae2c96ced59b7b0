// The fixed set of plane orientations of the restricted BSP tree (Kammaje &
// Mora 2007, "A study of restricted BSP trees for ray tracing"; Budge et al.
// 2008): the three axes, the four cube diagonals and the six face diagonals,
// 13 in all. A plane is n . p = s for one of these normals n.
//
// The normals are kept unnormalized, with components in {-1, 0, 1}: n . p of
// a float point is then a sum of at most three floats, which float64 gets
// within 2^-52 |p|_1 (the rounding bounds in the builder and the traversal
// rest on this), and the three axes are exactly the kd-tree's planes. The
// order matters: a tree with `directions` = 3, 7 or 13 uses the first ones.
//
// Thread-safety: constants and pure functions.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "core/geometry/vec3.h"

namespace outcore {

inline constexpr uint32_t kBspDirectionCount = 13;

inline constexpr std::array<std::array<int, 3>, kBspDirectionCount> kBspDirections{{
    {1, 0, 0},
    {0, 1, 0},
    {0, 0, 1},
    {1, 1, 1},
    {1, 1, -1},
    {1, -1, 1},
    {-1, 1, 1},
    {1, 1, 0},
    {1, -1, 0},
    {1, 0, 1},
    {1, 0, -1},
    {0, 1, 1},
    {0, 1, -1},
}};

// n_k . p in float64 (exact but for the final rounding of each of the at most
// two additions).
template <class T>
inline double bsp_dot(uint32_t k, const Vec3<T>& p) {
  const auto& n = kBspDirections[k];
  double sum = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    if (n[axis] > 0) sum += static_cast<double>(p[axis]);
    if (n[axis] < 0) sum -= static_cast<double>(p[axis]);
  }
  return sum;
}

inline Vec3d bsp_normal(uint32_t k) {
  const auto& n = kBspDirections[k];
  return {static_cast<double>(n[0]), static_cast<double>(n[1]), static_cast<double>(n[2])};
}

// |n_k|_2: 1, sqrt(3) or sqrt(2).
inline double bsp_normal_length(uint32_t k) {
  const auto& n = kBspDirections[k];
  return std::sqrt(static_cast<double>(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]));
}

}  // namespace outcore
