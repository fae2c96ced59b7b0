// Test helpers for the brick-structure tests (core/accel/*_test.cpp only):
// bricks from models and generators, synthetic bricks (random, degenerate-heavy),
// bricks resized to an exact triangle count, and random ray sets.
//
// Thread-safety: plain functions.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/source/source_factory.h"
#include "core/store/brick_data.h"

namespace outcore::accel_test {

// All triangles of an input (file or gen: spec) as one brick, ids (geometry_id, k).
inline BrickData load_brick_from(const std::string& spec, uint32_t geometry_id = 0) {
  BrickData brick;
  auto triangles = read_all_triangles(spec);
  EXPECT_TRUE(triangles.ok()) << spec << ": " << triangles.status().to_string();
  if (!triangles.ok()) return brick;
  brick.triangles = std::move(*triangles);
  for (uint32_t k = 0; k < brick.triangles.size(); ++k) brick.ids.push_back({geometry_id, k});
  return brick;
}

inline std::string bunny_path() {
  return std::string(OUTCORE_MODELS_DIR) + "/stanford-bunny.obj";
}

inline Aabb bounds_of(const BrickData& brick) {
  Aabb b;
  for (const Triangle& t : brick.triangles) b.extend(t.bounds());
  return b;
}

// Exactly n triangles: the first n of `base`, or copies of it side by side
// (shifted along x by 1.5 times its width) until n are reached. Ids stay
// distinct: copy c uses geometry_id c.
inline BrickData resized(const BrickData& base, uint64_t n) {
  BrickData out;
  out.triangles.reserve(n);
  out.ids.reserve(n);
  const Aabb b = bounds_of(base);
  const float shift = 1.5f * (b.hi.x - b.lo.x);
  for (uint64_t i = 0; i < n; ++i) {
    const uint64_t copy = i / base.triangles.size();
    const uint64_t k = i % base.triangles.size();
    Triangle t = base.triangles[k];
    const Vec3f offset(shift * static_cast<float>(copy), 0, 0);
    t.v0 = t.v0 + offset;
    t.v1 = t.v1 + offset;
    t.v2 = t.v2 + offset;
    out.triangles.push_back(t);
    out.ids.push_back({base.ids[k].geometry_id + static_cast<uint32_t>(copy), base.ids[k].primitive_id});
  }
  return out;
}

inline Vec3f random_point(std::mt19937_64& rng, const Vec3f& lo, const Vec3f& hi) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  return {lo.x + (hi.x - lo.x) * u(rng), lo.y + (hi.y - lo.y) * u(rng), lo.z + (hi.z - lo.z) * u(rng)};
}

// n triangles with vertices uniform in the unit cube: large, overlapping,
// the worst case for spatial splits.
inline BrickData random_triangles(uint64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  BrickData out;
  for (uint32_t k = 0; k < n; ++k) {
    const Vec3f lo(0, 0, 0), hi(1, 1, 1);
    out.triangles.push_back(
        {random_point(rng, lo, hi), random_point(rng, lo, hi), random_point(rng, lo, hi)});
    out.ids.push_back({0, k});
  }
  return out;
}

// n small triangles (edges up to 0.01) scattered uniformly in the unit cube:
// no spatial coherence at all, the worst case for Embree's leaf filling.
inline BrickData scattered_triangles(uint64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  BrickData out;
  const Vec3f lo(-0.01f, -0.01f, -0.01f), hi(0.01f, 0.01f, 0.01f);
  for (uint32_t k = 0; k < n; ++k) {
    const Vec3f a = random_point(rng, {0, 0, 0}, {1, 1, 1});
    out.triangles.push_back({a, a + random_point(rng, lo, hi), a + random_point(rng, lo, hi)});
    out.ids.push_back({0, k});
  }
  return out;
}

// n small random triangles, every other one degenerate (repeated or collinear
// vertices).
inline BrickData degenerate_heavy(uint64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  BrickData out;
  for (uint32_t k = 0; k < n; ++k) {
    const Vec3f a = random_point(rng, {0, 0, 0}, {1, 1, 1});
    const Vec3f d = random_point(rng, {-0.01f, -0.01f, -0.01f}, {0.01f, 0.01f, 0.01f});
    const Vec3f e = random_point(rng, {-0.01f, -0.01f, -0.01f}, {0.01f, 0.01f, 0.01f});
    Triangle t{a, a + d, a + e};
    if (k % 4 == 1) t = {a, a, a + e};          // repeated vertex
    if (k % 4 == 3) t = {a, a + d, a + d + d};  // collinear (exact in float64? not always)
    out.triangles.push_back(t);
    out.ids.push_back({0, k});
  }
  return out;
}

// n rays from random points on a sphere around `b` (radius 1.5x its half
// diagonal) towards random points inside `b`; direction lengths vary in [0.5, 2].
inline std::vector<Ray> rays_from_outside(const Aabb& b, uint64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> scale(0.5, 2.0);
  const Vec3d center = (Vec3d(b.lo) + Vec3d(b.hi)) * 0.5;
  const double radius = 1.5 * length(Vec3d(b.hi) - Vec3d(b.lo)) * 0.5;
  std::vector<Ray> rays(n);
  for (Ray& r : rays) {
    const Vec3d dir = normalize(Vec3d(g(rng), g(rng), g(rng)));
    const Vec3d origin = center + dir * radius;
    const Vec3d target(random_point(rng, b.lo, b.hi));
    r.origin = Vec3f(origin);
    r.direction = Vec3f(normalize(target - origin) * scale(rng));
  }
  return rays;
}

// n rays from random points inside `b` in random directions.
inline std::vector<Ray> rays_from_inside(const Aabb& b, uint64_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Ray> rays(n);
  for (Ray& r : rays) {
    r.origin = random_point(rng, b.lo, b.hi);
    r.direction = Vec3f(normalize(Vec3d(g(rng), g(rng), g(rng))));
  }
  return rays;
}

inline std::vector<uint32_t> all_ids(std::size_t n) {
  std::vector<uint32_t> ids(n);
  for (uint32_t i = 0; i < n; ++i) ids[i] = i;
  return ids;
}

}  // namespace outcore::accel_test
