// Boxes and rays on an integer grid for the upper-traversal tests: boxes that
// overlap, coincide, are flat (zero extent on an axis) or are points, and
// rays whose origins lie on grid planes or whose directions have zero
// components, so that slab planes, NaN slabs and equal entries all occur.
//
// Thread-safety: pure functions of the generator they are given.
#pragma once

#include <cstddef>
#include <random>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/ray/ray_types.h"

namespace outcore::testing {

// `n` boxes with corners on the grid [-half, half]^3, y scaled by `y_scale`
// (a flat city of boxes when below 1); about a fifth coincide with the
// previous box.
inline std::vector<Aabb> grid_boxes(std::size_t n, std::mt19937& rng, int half, float y_scale = 1.0f) {
  std::uniform_int_distribution<int> cell(-half, half), kind(0, 4);
  std::vector<Aabb> boxes;
  for (std::size_t i = 0; i < n; ++i) {
    Aabb b;
    const Vec3f lo(float(cell(rng)), float(cell(rng)) * y_scale, float(cell(rng)));
    b.extend(lo);
    switch (kind(rng)) {
      case 0: b.extend(lo + Vec3f(1, 1, 1)); break;
      case 1: b.extend(lo + Vec3f(2, 0, 1)); break;  // flat in y
      case 2: b.extend(lo + Vec3f(0.5f, 3, 0.25f)); break;
      case 3: b.extend(lo + Vec3f(3, 0.5f, 3)); break;
      default: break;  // a point
    }
    if (i > 0 && kind(rng) == 0) b = boxes[i - 1];  // coinciding with the previous one
    boxes.push_back(b);
  }
  return boxes;
}

// A ray from inside [-half, half]^3 (on grid planes a quarter of the time; y
// scaled by `y_scale`), with zero direction components a quarter of the time
// each, a segment ending at half / 2 or starting at 0.5 a quarter of the time.
inline Ray grid_ray(std::mt19937& rng, int half, float y_scale = 1.0f) {
  std::uniform_int_distribution<int> cell(-half, half), pick(0, 3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Ray r;
  r.origin = pick(rng) == 0 ? Vec3f(float(cell(rng)), float(cell(rng)) * y_scale, float(cell(rng)))
                            : Vec3f(half * u(rng), half * u(rng), half * u(rng));
  r.direction = Vec3f(pick(rng) == 0 ? 0.0f : u(rng), pick(rng) == 0 ? 0.0f : u(rng), u(rng));
  if (r.direction == Vec3f(0, 0, 0)) r.direction = {0, 0, 1};
  if (pick(rng) == 0) r.tfar = 0.5f * float(half);
  if (pick(rng) == 0) r.tnear = 0.5f;
  return r;
}

}  // namespace outcore::testing
