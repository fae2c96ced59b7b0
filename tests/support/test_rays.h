// Ray batches for the server and client tests: rays from around and inside a
// box towards points in it, directions of varied length, every fourth with a
// limited [tnear, tfar] — hits, misses and several bricks in one batch.
//
// Thread-safety: pure function.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/ray/ray_types.h"

namespace outcore::testing {

// A uniform point of the box grown by `grow` times its extent on each side.
template <class Rng>
Vec3f random_point_in(Rng& rng, const Aabb& box, float grow) {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const Vec3f e = box.extent();
  return {box.lo.x - grow * e.x + unit(rng) * (1 + 2 * grow) * e.x,
          box.lo.y - grow * e.y + unit(rng) * (1 + 2 * grow) * e.y,
          box.lo.z - grow * e.z + unit(rng) * (1 + 2 * grow) * e.z};
}

inline std::vector<Ray> make_test_rays(const Aabb& box, std::size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  auto point = [&](float grow) { return random_point_in(rng, box, grow); };
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f from = point(0.5f);
    const Vec3f to = point(0.0f);
    const float scale = 0.25f + 3.0f * unit(rng);
    rays[i].origin = from;
    rays[i].direction = Vec3f((to.x - from.x) * scale, (to.y - from.y) * scale, (to.z - from.z) * scale);
    if (i % 4 == 3) {
      rays[i].tnear = 0.2f * unit(rng);
      rays[i].tfar = rays[i].tnear + 0.8f * unit(rng);
    }
  }
  return rays;
}

}  // namespace outcore::testing
