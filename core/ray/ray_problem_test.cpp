// ray_is_valid() against ray_problem(): the same verdict on every ray built
// from components that sit on each rule's edge (zeros of both signs, the
// largest allowed component and the next float beyond, infinities, NaN).
#include "core/ray/ray_problem.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

std::vector<float> edge_values() {
  const float inf = std::numeric_limits<float>::infinity();
  const float big = kLargestRayComponent;
  return {0.0f,
          -0.0f,
          1.0f,
          -1.0f,
          1e-30f,
          big,
          -big,
          std::nextafter(big, inf),
          -std::nextafter(big, inf),
          inf,
          -inf,
          std::numeric_limits<float>::quiet_NaN(),
          std::numeric_limits<float>::denorm_min()};
}

TEST(RayIsValid, AgreesWithRayProblemOnEveryRuleEdge) {
  const std::vector<float> values = edge_values();
  std::mt19937 rng(5);
  std::uniform_int_distribution<std::size_t> pick(0, values.size() - 1);
  std::size_t valid = 0;
  for (int i = 0; i < 200000; ++i) {
    Ray ray;
    // Mostly ordinary components, so that each rule is often the only one broken.
    auto component = [&] { return rng() % 4 == 0 ? values[pick(rng)] : 0.5f; };
    ray.origin = {component(), component(), component()};
    ray.direction = {component(), component(), component()};
    if (rng() % 3 == 0) ray.direction = {values[pick(rng)], 0.0f, rng() % 2 ? -0.0f : 0.0f};
    ray.tnear = rng() % 2 ? values[pick(rng)] : 0.0f;
    ray.tfar = rng() % 2 ? values[pick(rng)] : std::numeric_limits<float>::infinity();
    const bool expected = ray_problem(ray) == nullptr;
    ASSERT_EQ(ray_is_valid(ray), expected)
        << "origin " << ray.origin.x << " " << ray.origin.y << " " << ray.origin.z << " direction "
        << ray.direction.x << " " << ray.direction.y << " " << ray.direction.z << " tnear " << ray.tnear
        << " tfar " << ray.tfar << ": " << (expected ? "valid" : ray_problem(ray));
    valid += expected;
  }
  EXPECT_GT(valid, 10000u);
  EXPECT_LT(valid, 190000u);
}

TEST(RayIsValid, EqualSegmentEndsAndZeroTnearAreValid) {
  Ray ray;
  ray.direction = {0.0f, 0.0f, -0.0f};
  EXPECT_FALSE(ray_is_valid(ray));  // a zero direction, whatever the signs
  ray.direction = {0.0f, 0.0f, 1.0f};
  ray.tnear = -0.0f;
  EXPECT_TRUE(ray_is_valid(ray));
  ray.tnear = ray.tfar = 2.0f;
  EXPECT_TRUE(ray_is_valid(ray));
  ray.tfar = std::nextafter(2.0f, 0.0f);
  EXPECT_FALSE(ray_is_valid(ray));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
