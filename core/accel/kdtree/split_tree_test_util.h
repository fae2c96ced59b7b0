// Test helpers shared by the tests of the structures over triangle
// references (kd_tree_test.cpp, bsp/bsp_test.cpp, grid/uniform_grid_test.cpp):
// the brute force over a structure's own triangles with a given triangle
// test, the bitwise comparison of its walks (closest and any hit) against it
// for every test, and the rays they use. Walks names the traversal:
// closest<Test>(view, ray, hit) and any<Test>(view, ray); a view has
// triangles, records and validate().
//
// Thread-safety: test code; call from the test's thread.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/kdtree/split_tree.h"

namespace outcore::split_tree_test {

// The brick's usable triangles (finite, not degenerate) and their ids.
inline BrickData usable(const BrickData& brick) {
  BrickData out;
  for (std::size_t k = 0; k < brick.triangles.size(); ++k) {
    if (!brick.triangles[k].is_finite() || brick.triangles[k].is_degenerate()) continue;
    out.triangles.push_back(brick.triangles[k]);
    out.ids.push_back(brick.ids[k]);
  }
  return out;
}

// Brute force with Test over the tree's own triangles.
template <class Test, class View>
void brute_force(const View& tree, const Ray& ray, Hit& best, bool& any) {
  const typename Test::Prepared prepared = Test::prepare(ray);
  const float tfar = ray.tfar < best.t ? ray.tfar : best.t;
  uint32_t found = kInvalidId;
  TriangleHit found_hit{};
  float limit = tfar;
  any = false;
  if (!(limit > ray.tnear)) return;
  for (uint32_t k = 0; k < tree.triangles.size(); ++k) {
    TriangleHit h;
    if (!Test::hit(prepared, tree.triangles[k], ray.tnear, ray.tfar, h)) continue;
    any = true;
    if (h.t > limit) continue;
    if (!hit_is_better(h.t, tree.records[k].geometry_id, tree.records[k].primitive_id, best)) continue;
    best.t = h.t;
    best.geometry_id = tree.records[k].geometry_id;
    best.primitive_id = tree.records[k].primitive_id;
    found = k;
    found_hit = h;
    limit = h.t;
  }
  if (found == kInvalidId) return;
  best.u = found_hit.u;
  best.v = found_hit.v;
  best.normal = tree.records[found].normal;
}

template <class Test, class Walks, class Tree>
void expect_matches_brute_force(const std::string& what, const Tree& tree, const std::vector<Ray>& rays,
                                std::size_t min_hits) {
  const auto view = tree.view();
  std::size_t hits = 0, differ = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Hit want, got;
    bool want_any = false;
    brute_force<Test>(view, rays[i], want, want_any);
    Walks::template closest<Test>(view, rays[i], got);
    hits += want.is_hit();
    if (std::memcmp(&want, &got, sizeof(Hit)) != 0 && differ++ < 5) {
      ADD_FAILURE() << what << " ray " << i << ": t " << got.t << " vs " << want.t << ", ids "
                    << got.geometry_id << "/" << got.primitive_id << " vs " << want.geometry_id << "/"
                    << want.primitive_id;
    }
    if (Walks::template any<Test>(view, rays[i]) != want_any && differ++ < 5) {
      ADD_FAILURE() << what << " ray " << i << ": any hit " << !want_any << " vs " << want_any;
    }
  }
  EXPECT_EQ(differ, 0u) << what;
  EXPECT_GE(hits, min_hits) << what;
}

// Every triangle test, bitwise against its brute force.
template <class Walks, class Tree>
void expect_every_test_matches(const std::string& what, const Tree& tree, const std::vector<Ray>& rays,
                               std::size_t min_hits) {
  ASSERT_TRUE(tree.view().validate().ok()) << what;
  expect_matches_brute_force<WatertightTriangleTest, Walks>(what + " watertight", tree, rays, min_hits);
  expect_matches_brute_force<MtTriangleTest, Walks>(what + " mt", tree, rays, min_hits / 2);
  expect_matches_brute_force<DoubleTriangleTest, Walks>(what + " double", tree, rays, min_hits);
}

// Rays from outside and inside the brick's box, some with short, shifted or
// negative-start segments.
inline std::vector<Ray> mixed_rays(const BrickData& brick, std::size_t n, uint64_t seed) {
  const Aabb b = accel_test::bounds_of(brick);
  auto rays = accel_test::rays_from_outside(b, n / 2, seed);
  const auto inside = accel_test::rays_from_inside(b, n - n / 2, seed + 1);
  rays.insert(rays.end(), inside.begin(), inside.end());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (i % 7 == 3) rays[i].tfar = 0.3f * length(b.extent());
    if (i % 11 == 5) rays[i].tnear = 0.05f * length(b.extent());
    if (i % 13 == 6) rays[i].tnear = -0.5f * length(b.extent());
  }
  return rays;
}

// A structure through the factory: `name` made with no options (and named
// so) and with the options in `good`; each option set in `bad` refused
// with an error naming its key; a brick built through it stays within its
// reservation and answers 500 mixed rays bitwise as brute force with the
// watertight test over `tree` (the same structure built directly from
// `brick`), at least min_hits of them hits.
template <class Tree>
void expect_the_factory_makes(const std::string& name, const BrickAccelOptions& good,
                              const std::vector<BrickAccelOptions>& bad, const BrickData& brick,
                              const Tree& tree, std::size_t min_hits) {
  auto builder = make_brick_builder(name, {});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_EQ((*builder)->name(), name);
  EXPECT_TRUE(make_brick_builder(name, good).ok());
  for (const BrickAccelOptions& options : bad) {
    const auto made = make_brick_builder(name, options);
    ASSERT_FALSE(made.ok()) << options.begin()->first;
    EXPECT_NE(made.status().message().find(options.begin()->first), std::string::npos)
        << made.status().message();
  }
  auto accel = (*builder)->build(BrickData(brick));
  ASSERT_TRUE(accel.ok()) << accel.status().to_string();
  EXPECT_LE((*accel)->memory_bytes(),
            (*builder)->reserve_bytes(static_cast<uint32_t>(brick.triangles.size())));
  const std::vector<Ray> rays = mixed_rays(brick, 500, 31);
  std::vector<Hit> got(rays.size());
  (*accel)->intersect(accel_test::all_ids(rays.size()), rays.data(), got.data());
  std::size_t hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Hit want;
    bool any = false;
    brute_force<WatertightTriangleTest>(tree.view(), rays[i], want, any);
    hits += want.is_hit();
    EXPECT_EQ(std::memcmp(&want, &got[i], sizeof(Hit)), 0) << name << " ray " << i;
  }
  EXPECT_GE(hits, min_hits) << name;
}

// Every triangle test, bitwise against brute force, on the scenes every
// structure's test runs: three generated meshes, random, scattered and
// degenerate-heavy soups, and the bunny; build(brick) makes the structure,
// `rays` rays a scene.
template <class Walks, class Build>
void expect_every_test_matches_on_the_usual_scenes(Build&& build, std::size_t rays) {
  for (const char* spec :
       {"gen:sphere?level=4", "gen:torus?nu=48&nv=24", "gen:terrain?n=24&size=6&height=0.5"}) {
    const BrickData brick = accel_test::load_brick_from(spec);
    expect_every_test_matches<Walks>(spec, build(brick), mixed_rays(brick, rays, 21), rays / 10);
  }
  const BrickData random = accel_test::random_triangles(1500, 4);
  expect_every_test_matches<Walks>("random", build(random), mixed_rays(random, rays, 22), rays / 10);
  const BrickData scattered = accel_test::scattered_triangles(3000, 5);
  expect_every_test_matches<Walks>("scattered", build(scattered), mixed_rays(scattered, rays, 23), 1);
  const BrickData degenerate = accel_test::degenerate_heavy(3000, 6);
  expect_every_test_matches<Walks>("degenerate", build(degenerate), mixed_rays(degenerate, rays, 24), 1);
  const BrickData bunny = accel_test::load_brick_from(accel_test::bunny_path());
  expect_every_test_matches<Walks>("bunny", build(bunny), mixed_rays(bunny, rays, 25), rays / 10);
}

// A closed icosphere (level 3) moved to `offset` and scaled with it, and rays
// from an interior point aimed exactly at every vertex and edge midpoint
// (direction = target - origin in float): a watertight walk leaks none.
struct AimedSphere {
  BrickData sphere;
  std::vector<Ray> rays;
};
inline AimedSphere aimed_sphere(float offset) {
  AimedSphere out;
  out.sphere = accel_test::load_brick_from("gen:sphere?level=3");
  const float scale = std::max(1.0f, offset * 1e-3f);
  for (Triangle& tri : out.sphere.triangles) {
    for (Vec3f* v : {&tri.v0, &tri.v1, &tri.v2}) *v = *v * scale + Vec3f(offset, -0.5f * offset, offset);
  }
  const Vec3f interior = accel_test::bounds_of(out.sphere).center() + Vec3f(0.01f, 0.02f, -0.03f) * scale;
  for (const Triangle& tri : out.sphere.triangles) {
    for (const Vec3f& target : {tri.v0, tri.v1, tri.v2, (tri.v0 + tri.v1) * 0.5f, (tri.v1 + tri.v2) * 0.5f}) {
      Ray ray;
      ray.origin = interior;
      ray.direction = target - interior;
      out.rays.push_back(ray);
    }
  }
  return out;
}

}  // namespace outcore::split_tree_test
