// The bricks' bounding sphere and oriented box (bounding_sphere.h,
// oriented_box.h): every vertex inside, at offsets up to 1e6; the oriented
// box of oblique thin geometry far smaller than its AABB and never larger in
// area; and conservative ray tests: a ray that the watertight or the
// Moeller-Trumbore test reports a hit for, within its segment, is never
// rejected (rays aimed at vertices, edge midpoints and random points of the
// triangles, from near and far, segments ending just at the hit), while rays
// that pass far away are.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/geometry/hit_rounding.h"
#include "core/upper/bounding_sphere.h"
#include "core/upper/oriented_box.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Brute force per ray: fewer under the sanitizers' Debug build.
#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kAimedRays = 500;
#else
constexpr std::size_t kAimedRays = 3000;
#endif

struct Scene {
  std::string name;
  std::vector<Triangle> triangles;
};

std::vector<Triangle> shifted(std::vector<Triangle> triangles, float offset) {
  const float scale = std::max(1.0f, offset * 1e-3f);
  for (Triangle& tri : triangles) {
    for (Vec3f* v : {&tri.v0, &tri.v1, &tri.v2}) *v = *v * scale + Vec3f(offset, -0.5f * offset, offset);
  }
  return triangles;
}

std::vector<Scene> scenes() {
  std::vector<Scene> out;
  const auto load = [](const std::string& spec) { return accel_test::load_brick_from(spec).triangles; };
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const std::string at = " +" + std::to_string(static_cast<int>(offset));
    out.push_back({"bunny" + at, shifted(load(accel_test::bunny_path()), offset)});
    out.push_back({"tilted city" + at,
                   shifted(load("gen:city?of=(gen:sphere?level=1)&copies=16&spacing=3&tilt=30"), offset)});
    out.push_back({"soup" + at, shifted(accel_test::random_triangles(300, 5).triangles, offset)});
  }
  out.push_back({"one triangle", {Triangle{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)}}});
  return out;
}

TEST(BrickBoundingVolumes, EveryVertexIsInsideBoth) {
  for (const Scene& scene : scenes()) {
    const BoundingSphere sphere = BoundingSphere::fit(scene.triangles);
    const OrientedBox box = OrientedBox::fit(scene.triangles);
    ASSERT_FALSE(sphere.empty()) << scene.name;
    ASSERT_FALSE(box.empty()) << scene.name;
    for (const Triangle& tri : scene.triangles) {
      for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
        ASSERT_LE(length(Vec3d(v) - Vec3d(sphere.center)), static_cast<double>(sphere.radius)) << scene.name;
        for (int k = 0; k < 3; ++k) {
          const double projection = dot(Vec3d(box.axes[k]), Vec3d(v));
          ASSERT_GE(projection, static_cast<double>(box.lo[k])) << scene.name << " axis " << k;
          ASSERT_LE(projection, static_cast<double>(box.hi[k])) << scene.name << " axis " << k;
        }
      }
    }
  }
  EXPECT_TRUE(BoundingSphere::fit({}).empty());
  EXPECT_TRUE(OrientedBox::fit({}).empty());
}

double aabb_area(const std::vector<Triangle>& triangles) {
  Aabb box;
  for (const Triangle& tri : triangles) box.extend(tri.bounds());
  const Vec3d e = Vec3d(box.hi) - Vec3d(box.lo);
  return 2 * (e.x * e.y + e.y * e.z + e.z * e.x);
}

TEST(BrickBoundingVolumes, TheOrientedBoxFindsObliqueThinGeometryAndIsNeverLargerThanTheAabb) {
  // A thin slab of the city turned 30 degrees: its box is far smaller.
  const auto slab =
      accel_test::load_brick_from("gen:city?of=(gen:sphere?level=1)&copies=64&spacing=3&tilt=30");
  const OrientedBox box = OrientedBox::fit(slab.triangles);
  Aabb aabb;
  for (const Triangle& tri : slab.triangles) aabb.extend(tri.bounds());
  const Vec3d e = Vec3d(aabb.hi) - Vec3d(aabb.lo);
  EXPECT_LT(box.volume(), 0.35 * e.x * e.y * e.z);
  for (const Scene& scene : scenes()) {
    // Within the outward rounding of its float slabs (at offsets up to 1e6 of
    // a unit soup, ~1e-4 of its size).
    EXPECT_LE(OrientedBox::fit(scene.triangles).surface_area(), aabb_area(scene.triangles) * 1.001)
        << scene.name;
  }
}

// Rays towards points of the triangles (vertices, edge midpoints, random
// inner points) from origins around the scene, near and far.
std::vector<Ray> aimed_rays(const std::vector<Triangle>& triangles, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Aabb box;
  for (const Triangle& tri : triangles) box.extend(tri.bounds());
  const Vec3f e = box.extent();
  const float reach = std::max({e.x, e.y, e.z});
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Triangle& tri = triangles[rng() % triangles.size()];
    Vec3f target;
    switch (i % 3) {
      case 0: target = i % 2 ? tri.v0 : tri.v2; break;
      case 1: target = (tri.v0 + tri.v1) * 0.5f; break;
      default: {
        float a = u(rng), b = u(rng);
        if (a + b > 1) a = 1 - a, b = 1 - b;
        target = tri.v0 + (tri.v1 - tri.v0) * a + (tri.v2 - tri.v0) * b;
      }
    }
    const float distance = (i % 4 == 0 ? 50.0f : 1.5f) * reach;
    const Vec3f dir(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f);
    rays[i].origin = target + dir * (distance / std::max(1e-3f, length(dir)));
    rays[i].direction = target - rays[i].origin;
  }
  return rays;
}

template <class Test>
void expect_no_hit_is_rejected(const Scene& scene, double rounding, const std::string& test_name) {
  const BoundingSphere sphere = BoundingSphere::fit(scene.triangles);
  const OrientedBox box = OrientedBox::fit(scene.triangles);
  const auto rays = aimed_rays(scene.triangles, kAimedRays, 7);
  std::size_t hits = 0, rejected = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Ray ray = rays[i];
    const typename Test::Prepared prepared = Test::prepare(ray);
    float nearest = ray.tfar;
    bool any = false;
    for (const Triangle& tri : scene.triangles) {
      TriangleHit h;
      if (Test::hit(prepared, tri, ray.tnear, nearest, h)) {
        nearest = h.t;
        any = true;
      }
    }
    if (!any) continue;
    ++hits;
    // The segment ends exactly at the hit: the tightest a caller asks.
    for (const float tfar : {ray.tfar, nearest}) {
      rejected += !sphere.may_hit(ray, ray.tnear, tfar, rounding);
      rejected += !box.may_hit(ray, ray.tnear, tfar, rounding);
    }
  }
  EXPECT_GT(hits, rays.size() / 2) << scene.name << " " << test_name;
  EXPECT_EQ(rejected, 0u) << scene.name << " " << test_name;
}

TEST(BrickBoundingVolumes, ARayATriangleTestHitsIsNeverRejected) {
  for (const Scene& scene : scenes()) {
    expect_no_hit_is_rejected<WatertightTriangleTest>(scene, kWatertightHitRounding, "watertight");
    expect_no_hit_is_rejected<MtTriangleTest>(scene, kMollerTrumboreHitRounding, "mt");
  }
}

TEST(BrickBoundingVolumes, RaysPassingFarAwayAreRejected) {
  const std::vector<Triangle> triangles = accel_test::load_brick_from(accel_test::bunny_path()).triangles;
  const BoundingSphere sphere = BoundingSphere::fit(triangles);
  const OrientedBox box = OrientedBox::fit(triangles);
  const float r = sphere.radius;
  const Vec3f c = sphere.center;
  // Parallel to x, 3 radii off in y: misses both.
  const Ray past{c + Vec3f(-10 * r, 3 * r, 0), Vec3f(1, 0, 0)};
  EXPECT_FALSE(sphere.may_hit(past, 0, past.tfar, kWatertightHitRounding));
  EXPECT_FALSE(box.may_hit(past, 0, past.tfar, kWatertightHitRounding));
  // Through the centre but the segment ends before the bounds / starts after.
  const Ray through{c + Vec3f(-10 * r, 0, 0), Vec3f(1, 0, 0)};
  EXPECT_TRUE(sphere.may_hit(through, 0, through.tfar, kWatertightHitRounding));
  EXPECT_TRUE(box.may_hit(through, 0, through.tfar, kWatertightHitRounding));
  EXPECT_FALSE(sphere.may_hit(through, 0, 5 * r, kWatertightHitRounding));
  EXPECT_FALSE(box.may_hit(through, 0, 5 * r, kWatertightHitRounding));
  EXPECT_FALSE(sphere.may_hit(through, 15 * r, through.tfar, kWatertightHitRounding));
  EXPECT_FALSE(box.may_hit(through, 15 * r, through.tfar, kWatertightHitRounding));
  // Pointing away.
  const Ray away{c + Vec3f(-10 * r, 0, 0), Vec3f(-1, 0, 0)};
  EXPECT_FALSE(sphere.may_hit(away, 0, away.tfar, kWatertightHitRounding));
  EXPECT_FALSE(box.may_hit(away, 0, away.tfar, kWatertightHitRounding));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
