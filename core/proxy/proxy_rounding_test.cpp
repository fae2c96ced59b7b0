// The proxies' rounding bound E (brick_proxy.h) against what every brick
// structure's float triangle test actually accepts: rays aimed at and up to
// 4096 float epsilons outside the edges and corners of small, far, thin,
// sliver and large triangles, from origins anywhere within the scene's
// reach, a third of them grazing. Every hit a watertight structure reports
// lies within its E of the triangle (the exact ray, in float64), and the
// brick's proxy answers "may hit" for it; Moeller-Trumbore structures get the
// same for their hits within their E, and the ones beyond (grazing
// acceptances, which have no bound) are counted and printed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "core/proxy/proxy_builder.h"
#include "core/stress/stress_runner.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Euclidean distance (an upper bound of the max-norm one E bounds) between
// the exact line o + t d and a triangle, in float64. Differences of floats are
// exact in float64 at these magnitudes; the cross products keep the result
// free of the cancellation |w|^2 - (w.d)^2 would suffer.
double line_triangle_distance(const Vec3d& o, const Vec3d& d, const Triangle& tri) {
  const Vec3d v[3] = {Vec3d(tri.v0) - o, Vec3d(tri.v1) - o, Vec3d(tri.v2) - o};
  // The line pierces the triangle when the three edge determinants agree.
  double det[3];
  for (int i = 0; i < 3; ++i) det[i] = dot(cross(v[i], v[(i + 1) % 3]), d);
  if ((det[0] >= 0 && det[1] >= 0 && det[2] >= 0) || (det[0] <= 0 && det[1] <= 0 && det[2] <= 0)) {
    if (!(det[0] == 0 && det[1] == 0 && det[2] == 0)) return 0.0;
  }
  // Otherwise the nearest point is on an edge: |(w0 + s e) x d| / |d| is
  // minimised over s in [0, 1] (a convex quadratic in s).
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    const Vec3d a = cross(v[i], d), b = cross(v[(i + 1) % 3] - v[i], d);
    const double bb = dot(b, b);
    double s = bb > 0 ? -dot(a, b) / bb : 0.0;
    s = std::clamp(s, 0.0, 1.0);
    for (const double si : {s, 0.0, 1.0}) best = std::min(best, length(a + b * si));
  }
  return best / length(d);
}

struct Case {
  const char* name;
  Vec3f centre;
  float spread;  // triangles lie within centre +- spread
  float size;    // their edge length
  float sliver;  // the third vertex's offset from the first edge, relative
};

std::vector<Triangle> scattered_triangles(std::mt19937_64& rng, const Case& c, int n) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Triangle> out;
  for (int i = 0; i < n; ++i) {
    const Vec3f p = c.centre + Vec3f(u(rng), u(rng), u(rng)) * c.spread;
    const Vec3f e1 = normalize(Vec3f(u(rng), u(rng), u(rng))) * c.size;
    const Vec3f side = normalize(cross(e1, Vec3f(u(rng), u(rng), u(rng))));
    out.push_back({p, p + e1, p + e1 * (0.2f + 0.6f * (u(rng) + 1) / 2) + side * (c.size * c.sliver)});
  }
  return out;
}

TEST(ProxyRounding, EveryStructuresAcceptedHitsLieWithinTheRoundingBound) {
  // The 100 M city's situation (3-unit bricks of 0.06-unit triangles 300
  // units out, rays from 600-900 units away) and harder ones.
  const Case cases[] = {
      {"small, far", {290, 0, 290}, 1.6f, 0.06f, 0.5f},
      {"slivers, far", {-250, 1, 120}, 1.6f, 0.2f, 1e-3f},
      {"large, near the origin", {0, 0, 0}, 20, 8, 0.7f},
      {"tiny, very far", {3000, -2000, 1000}, 0.5f, 0.01f, 0.4f},
      {"thin, far", {-250, 1, 120}, 1.6f, 0.2f, 1e-1f},
      {"thinner, far", {-250, 1, 120}, 1.6f, 0.2f, 1e-2f},
  };
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  constexpr double kEps = 0x1p-23;  // float's epsilon
  double worst_watertight = 0;
  for (const Case& c : cases) {
    const std::vector<Triangle> tris = scattered_triangles(rng, c, 400);
    Aabb box;
    for (const Triangle& t : tris) box.extend(t.bounds());
    // The scene: the brick and twice as much again around the world origin,
    // so the reach (proxy_origin_reach) covers the origins below.
    const float far =
        2 * std::max({std::fabs(c.centre.x), std::fabs(c.centre.y), std::fabs(c.centre.z), 300.0f});
    const Aabb scene{{-far / 2, -far / 2, -far / 2}, {far / 2, far / 2, far / 2}};
    Aabb scene_and_brick = scene;
    scene_and_brick.extend(box);
    const BrickProxy proxy = build_brick_proxy(box, scene_and_brick, tris, ProxyBuildConfig{});
    const double reach = proxy_origin_reach(scene_and_brick);
    const double domain = proxy.frame().domain_magnitude_WS();

    // Rays: aimed at a point of an edge (or a corner) pushed in or out within
    // the triangle's plane by up to 4096 float epsilons of the magnitudes
    // involved (log-uniformly), from a random origin within the reach; a third of them
    // grazing (nearly in the triangle's plane).
    std::vector<Ray> rays;
    for (int r = 0; r < 60000; ++r) {
      const Triangle& t = tris[r % tris.size()];
      const Vec3d a(t.v0), b(t.v1), cc(t.v2);
      const Vec3d corners[3] = {a, b, cc};
      const int edge = r % 3;
      const Vec3d p0 = corners[edge], p1 = corners[(edge + 1) % 3], opposite = corners[(edge + 2) % 3];
      const Vec3d n = normalize(cross(b - a, cc - a));
      Vec3d out = normalize(cross(p1 - p0, n));
      if (dot(out, opposite - p0) > 0) out = out * -1.0;
      const double s = (r % 7 == 0) ? 0.0 : (u(rng) + 1) / 2;
      Vec3d origin;
      if (r % 3 == 0) {
        const Vec3d in_plane = normalize(cross(n, Vec3d(u(rng), u(rng), u(rng))));
        origin = p0 + (in_plane + n * (std::pow(10.0, -1 - 3 * (u(rng) + 1) / 2))) * (reach * 0.6);
      } else {
        origin = Vec3d(u(rng), u(rng), u(rng)) * reach;
      }
      const double magnitude = max_abs(origin) + domain;
      const Vec3d aim =
          p0 + (p1 - p0) * s + out * (u(rng) * std::pow(2.0, 12 * (u(rng) + 1) / 2) * kEps * magnitude);
      Ray ray;
      ray.origin = Vec3f(origin);
      ray.direction = Vec3f(aim - Vec3d(ray.origin));
      if (ray.direction == Vec3f(0, 0, 0)) continue;
      rays.push_back(ray);
    }

    for (const StressConfig& config : stress_configs()) {
      auto builder = make_brick_builder(config.accel, config.options);
      ASSERT_TRUE(builder.ok()) << builder.status().to_string();
      BrickData brick;
      brick.triangles = tris;
      for (uint32_t k = 0; k < tris.size(); ++k) brick.ids.push_back({0, k});
      auto accel = (*builder)->build(std::move(brick));
      ASSERT_TRUE(accel.ok()) << accel.status().to_string();
      std::vector<uint32_t> ids(rays.size());
      for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
      std::vector<Hit> hits(rays.size());
      (*accel)->intersect(ids, rays.data(), hits.data());
      const double scale = (*builder)->hit_rounding_scale();
      const bool watertight = scale == kWatertightHitRounding;
      EXPECT_EQ(watertight, config.must_not_leak) << config.name;  // bvh-watertight and bvh-double
      uint64_t hit_count = 0, beyond = 0;
      double worst = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        if (!hits[i].is_hit()) continue;
        ++hit_count;
        const Ray& ray = rays[i];
        const Vec3d o(ray.origin), d(ray.direction);
        const double distance = line_triangle_distance(o, d, tris[hits[i].primitive_id]);
        const double bound = proxy_rounding_bound(scale, max_abs(o), domain);
        worst = std::max(worst, distance / (kEps * (max_abs(o) + domain)));
        if (watertight) {
          ASSERT_LE(distance, bound) << c.name << ", " << config.name << ", ray " << i;
        } else if (distance > bound) {
          ++beyond;  // a grazing acceptance the Moeller-Trumbore scale does not cover
          continue;
        }
        ASSERT_TRUE(proxy.may_hit(ray, ray.tnear, ray.tfar, scale))
            << c.name << ", " << config.name << ", ray " << i;
      }
      EXPECT_GT(hit_count, 1000u) << c.name << ", " << config.name;
      if (watertight) worst_watertight = std::max(worst_watertight, worst);
      std::printf(
          "  %-22s %-15s %6llu hits, farthest %8.3f float epsilons of |o| + |brick| from its triangle, %llu "
          "beyond E\n",
          c.name, config.name.c_str(), static_cast<unsigned long long>(hit_count), worst,
          static_cast<unsigned long long>(beyond));
    }
  }
  // The watertight bound keeps a factor of 16 over the worst hit measured here.
  EXPECT_LE(worst_watertight * 16 * kEps, kWatertightHitRounding);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
