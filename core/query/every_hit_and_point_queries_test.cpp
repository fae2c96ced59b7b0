// Every-hit (count / list) and point queries (closest points, occupancy)
// against float64 brute force over every triangle of the scene, across brick
// structures, strategies and budgets.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

#include "core/accel/brute_force_reference.h"
#include "core/geometry/closest_point_on_triangle.h"
#include "core/query/point_queries.h"
#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::PackedScene;

using testing::open_test_engine;

Vec3f random_in(std::mt19937_64& rng, const Aabb& box, float grow) {
  return testing::random_point_in(rng, box, grow);
}

std::vector<Ray> rays_through(const Aabb& box, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    rays[i].origin = random_in(rng, box, 0.5f);
    rays[i].direction = random_in(rng, box, 0.0f) - rays[i].origin;
    if (i % 5 == 0) rays[i].tfar = 0.7f;
    if (i % 7 == 0) rays[i].tnear = 0.2f;
  }
  return rays;
}

struct ExpectedHit {
  double t;
  TriangleId id;
};

// Every hit of the ray in float64, sorted by t then ids.
std::vector<ExpectedHit> reference_every_hit(const PackedScene& scene, const Ray& ray) {
  std::vector<ExpectedHit> hits;
  for (std::size_t k = 0; k < scene.triangles.size(); ++k) {
    if (const auto h = reference_triangle_hit(scene.triangles[k], ray)) hits.push_back({h->t, scene.ids[k]});
  }
  std::sort(hits.begin(), hits.end(), [](const ExpectedHit& a, const ExpectedHit& b) {
    if (a.t != b.t) return a.t < b.t;
    if (a.id.geometry_id != b.id.geometry_id) return a.id.geometry_id < b.id.geometry_id;
    return a.id.primitive_id < b.id.primitive_id;
  });
  return hits;
}

// Whether the float64 reference puts the ray within `margin` of a hit
// triangle's boundary, where float tests may rightly disagree.
bool grazes_an_edge(const PackedScene& scene, const Ray& ray, double margin = 1e-5) {
  for (const Triangle& tri : scene.triangles) {
    const auto h = reference_plane_hit(tri, ray);
    if (!h) continue;
    const double w = 1 - h->u - h->v;
    const double inside = std::min({h->u, h->v, w});
    if (std::abs(inside) < margin && h->t > ray.tnear - margin && h->t <= ray.tfar + margin) return true;
  }
  return false;
}

void expect_every_hit_matches_reference(const PackedScene& scene, QueryEngine& engine,
                                        const std::vector<Ray>& rays, const QueryOptions& options = {}) {
  std::vector<uint32_t> counts(rays.size());
  std::vector<RayHitRecord> records;
  ASSERT_TRUE(engine.all_hits(rays, counts, &records, options).ok());
  // Counting alone (BrickAccel::count_hits) gives the listed counts.
  std::vector<uint32_t> only_counts(rays.size());
  ASSERT_TRUE(engine.all_hits(rays, only_counts, nullptr, options).ok());
  EXPECT_EQ(only_counts, counts);
  std::size_t at = 0, checked = 0, hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const std::size_t begin = at;
    while (at < records.size() && records[at].ray == i) ++at;
    ASSERT_EQ(at - begin, counts[i]) << "ray " << i;
    if (grazes_an_edge(scene, rays[i])) continue;
    const auto expected = reference_every_hit(scene, rays[i]);
    ASSERT_EQ(counts[i], expected.size()) << "ray " << i;
    for (std::size_t k = 0; k < expected.size(); ++k) {
      const Hit& got = records[begin + k].hit;
      EXPECT_NEAR(got.t, expected[k].t, 1e-4 * std::max(1.0, expected[k].t)) << "ray " << i << " hit " << k;
      // Hits a few ulps apart in t may come in either order.
      if (k + 1 < expected.size() && std::abs(expected[k + 1].t - expected[k].t) < 1e-4) continue;
      if (k > 0 && std::abs(expected[k - 1].t - expected[k].t) < 1e-4) continue;
      EXPECT_EQ(got.geometry_id, expected[k].id.geometry_id) << "ray " << i << " hit " << k;
      EXPECT_EQ(got.primitive_id, expected[k].id.primitive_id) << "ray " << i << " hit " << k;
    }
    ++checked;
    hits += counts[i];
  }
  EXPECT_EQ(at, records.size());
  EXPECT_GT(checked, rays.size() * 9 / 10);
  EXPECT_GT(hits, rays.size());  // closed meshes: most rays that hit, hit twice or more
}

TEST(EveryHitQuery, CountsAndListsMatchFloat64BruteForceForEveryStructure) {
  const auto scene = testing::pack_test_scene(
      {"gen:sphere?level=3", "gen:torus?nu=32&nv=16&cx=1.5", "gen:terrain?n=12&size=6&height=0.5"}, 96);
  const std::vector<Ray> rays = rays_through(scene->bounds, 1500, 7);
  for (const std::string accel : {"bvh", "embree", "kdtree", "grid", "octree", "reference", "auto"}) {
    SCOPED_TRACE(accel);
    const auto engine = open_test_engine(*scene, accel);
    expect_every_hit_matches_reference(*scene, *engine, rays);
  }
}

// A budget of a quarter of the scene's brick reservations (at least the
// largest brick's, which the engine requires).
// A quarter of the bytes every brick takes once built (each built here),
// and room for two builds' reservations: reservations are worst cases, far
// above the built size for small bricks, so a quarter of the reservations
// could hold the whole scene and never evict.
uint64_t quarter_of_scene(const PackedScene& scene, const std::string& brick_accel) {
  const auto full = open_test_engine(scene, brick_accel);
  const BrickBuilder& builder = full->cache().builder();
  uint64_t built = 0, largest = 0;
  for (uint32_t id = 0; id < full->store().manifest().bricks.size(); ++id) {
    BrickData brick;
    EXPECT_TRUE(full->store().load_brick(id, brick).ok()) << id;
    largest = std::max(largest, builder.reserve_bytes(brick.triangles.size()));
    auto accel = builder.build(std::move(brick));
    EXPECT_TRUE(accel.ok()) << id;
    if (accel.ok()) built += (*accel)->memory_bytes();
  }
  return std::max(built / 4, 2 * largest);
}

TEST(EveryHitQuery, AnswersAreTheSameUnderAQuarterBudgetAndWithoutReordering) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5"}, 128);
  const std::vector<Ray> rays = rays_through(scene->bounds, 3000, 11);
  const auto full = open_test_engine(*scene, "bvh");
  std::vector<uint32_t> counts(rays.size());
  std::vector<RayHitRecord> records;
  ASSERT_TRUE(full->all_hits(rays, counts, &records, {}).ok());
  const auto tight = open_test_engine(*scene, "bvh", quarter_of_scene(*scene, "bvh"));
  for (const bool reorder : {true, false}) {
    std::vector<uint32_t> tight_counts(rays.size());
    std::vector<RayHitRecord> tight_records;
    QueryOptions options;
    options.reorder = reorder;
    QueryStats stats;
    ASSERT_TRUE(tight->all_hits(rays, tight_counts, &tight_records, options, &stats).ok());
    EXPECT_EQ(tight_counts, counts);
    ASSERT_EQ(tight_records.size(), records.size());
    for (std::size_t k = 0; k < records.size(); ++k) {
      EXPECT_EQ(tight_records[k].ray, records[k].ray);
      EXPECT_EQ(std::memcmp(&tight_records[k].hit, &records[k].hit, sizeof(Hit)), 0) << k;
    }
    if (reorder) {
      EXPECT_GT(stats.evictions, 0u);
    }
  }
  // Counting alone gives the same counts.
  std::vector<uint32_t> only_counts(rays.size());
  ASSERT_TRUE(full->all_hits(rays, only_counts, nullptr, {}).ok());
  EXPECT_EQ(only_counts, counts);
}

TEST(EveryHitQuery, RefusedWhileTheDynamicLayerHoldsInstancesAndWrongLengths) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=2"}, 64);
  const auto engine = open_test_engine(*scene, "bvh");
  const std::vector<Ray> rays = rays_through(scene->bounds, 10, 3);
  std::vector<uint32_t> wrong(rays.size() + 1);
  EXPECT_EQ(engine->all_hits(rays, wrong, nullptr, {}).code(), StatusCode::kInvalidArgument);
  const std::vector<float> vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const std::vector<uint32_t> triangles = {0, 1, 2};
  const auto mesh = engine->dynamic().add_mesh(vertices, triangles);
  ASSERT_TRUE(mesh.ok());
  const std::vector<double> identity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  ASSERT_TRUE(engine->dynamic().add_instance(mesh->id, identity).ok());
  std::vector<uint32_t> counts(rays.size());
  const Status refused = engine->all_hits(rays, counts, nullptr, {});
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_TRUE(testing::contains(refused.message(), "dynamic layer")) << refused.message();
  std::vector<ClosestPoint> closest(1);
  const std::vector<Vec3f> point = {{0, 0, 0}};
  EXPECT_EQ(engine->closest_points(point, closest, {}).code(), StatusCode::kFailedPrecondition);
}

// The float64 closest point over every triangle.
ClosestPoint reference_closest(const PackedScene& scene, const Vec3f& point) {
  ClosestPoint best;
  for (std::size_t k = 0; k < scene.triangles.size(); ++k) {
    if (scene.triangles[k].is_degenerate()) continue;
    offer_closest(Vec3d(point), scene.triangles[k], scene.ids[k].geometry_id, scene.ids[k].primitive_id,
                  scene.triangles[k].unit_normal(), best);
  }
  return best;
}

std::vector<Vec3f> points_around(const Aabb& box, std::size_t n, uint64_t seed, float grow) {
  std::mt19937_64 rng(seed);
  std::vector<Vec3f> points(n);
  for (Vec3f& p : points) p = random_in(rng, box, grow);
  return points;
}

TEST(ClosestPointQuery, MatchesFloat64BruteForceForEveryStructureAndBudget) {
  const auto scene = testing::pack_test_scene(
      {"gen:sphere?level=3", "gen:torus?nu=32&nv=16&cx=2.5", "gen:terrain?n=12&size=6&height=0.5"}, 80);
  std::vector<Vec3f> points = points_around(scene->bounds, 800, 5, 0.5f);
  // Points on the surface and at vertices: distance 0.
  for (std::size_t k = 0; k < scene->triangles.size(); k += 37) {
    points.push_back(scene->triangles[k].v1);
    points.push_back(scene->triangles[k].centroid());
  }
  std::vector<ClosestPoint> expected(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) expected[i] = reference_closest(*scene, points[i]);
  for (const std::string accel : {"bvh", "embree", "kdtree", "reference", "auto"}) {
    const uint64_t quarter = quarter_of_scene(*scene, accel);
    for (const uint64_t budget : {uint64_t{1} << 30, quarter}) {
      SCOPED_TRACE(accel + " budget " + std::to_string(budget));
      const auto engine = open_test_engine(*scene, accel, budget);
      std::vector<ClosestPoint> got(points.size());
      QueryStats stats;
      ASSERT_TRUE(engine->closest_points(points, got, {}, &stats).ok());
      for (std::size_t i = 0; i < points.size(); ++i) {
        ASSERT_TRUE(got[i].found()) << i;
        EXPECT_NEAR(std::sqrt(got[i].distance_squared), std::sqrt(expected[i].distance_squared),
                    1e-6 * std::max(1.0, std::sqrt(expected[i].distance_squared)))
            << "point " << i;
        if (got[i].distance_squared == expected[i].distance_squared) {
          EXPECT_EQ(got[i].geometry_id, expected[i].geometry_id) << i;
          EXPECT_EQ(got[i].primitive_id, expected[i].primitive_id) << i;
        }
        const double gap = length(Vec3d(got[i].point) - Vec3d(points[i]));
        EXPECT_NEAR(gap, std::sqrt(got[i].distance_squared), 1e-5 * std::max(1.0, gap)) << i;
      }
      EXPECT_EQ(stats.rays, points.size());
      EXPECT_EQ(stats.rays_hit, points.size());
      if (budget == quarter) {
        EXPECT_GT(stats.evictions, 0u);
      }
    }
  }
}

TEST(ClosestPointQuery, InvalidPointsAreCountedOrNamedUnderStrict) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=2"}, 64);
  const auto engine = open_test_engine(*scene, "bvh");
  std::vector<Vec3f> points = {{0.2f, 0.1f, 3.0f}, {NAN, 0, 0}, {0, 0, 1e19f}};
  std::vector<ClosestPoint> got(points.size());
  QueryStats stats;
  ASSERT_TRUE(engine->closest_points(points, got, {}, &stats).ok());
  EXPECT_TRUE(got[0].found());
  EXPECT_FALSE(got[1].found());
  EXPECT_FALSE(got[2].found());
  EXPECT_EQ(stats.invalid_rays, 2u);
  QueryOptions strict;
  strict.strict = true;
  const Status refused = engine->closest_points(points, got, strict);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(testing::contains(refused.message(), "point 1")) << refused.message();
}

// An axis-aligned cube [-1, 1]^3 as 12 triangles (closed, outward).
std::string write_cube(const testing::TempDir& dir) {
  const std::string path = dir.file("cube.obj");
  std::ofstream obj(path);
  for (int i = 0; i < 8; ++i)
    obj << "v " << (i & 1 ? 1 : -1) << ' ' << (i & 2 ? 1 : -1) << ' ' << (i & 4 ? 1 : -1) << '\n';
  // Faces (1-based), two triangles each, counter-clockwise seen from outside.
  const int quads[6][4] = {{1, 3, 4, 2}, {5, 6, 8, 7}, {1, 2, 6, 5},
                           {3, 7, 8, 4}, {1, 5, 7, 3}, {2, 4, 8, 6}};
  for (const auto& q : quads) {
    obj << "f " << q[0] << ' ' << q[1] << ' ' << q[2] << '\n';
    obj << "f " << q[0] << ' ' << q[2] << ' ' << q[3] << '\n';
  }
  return path;
}

TEST(OccupancyQuery, ExactInsideACubeEvenWhereTheFirstRayMeetsAnEdgeOrVertex) {
  testing::TempDir dir;
  const auto scene = testing::pack_test_scene({write_cube(dir)}, 4);
  const auto engine = open_test_engine(*scene, "bvh");
  std::vector<Vec3f> points;
  std::vector<uint8_t> expected;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  for (int k = 0; k < 400; ++k) {
    const Vec3f p{u(rng), u(rng), u(rng)};
    if (std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}) > 0.999f &&
        std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}) < 1.001f)
      continue;
    points.push_back(p);
    expected.push_back(std::abs(p.x) < 1 && std::abs(p.y) < 1 && std::abs(p.z) < 1);
  }
  // Points whose first ray leaves through a face diagonal (an edge shared by
  // two triangles) or a corner.
  const Vec3f d = occupancy_direction(0);
  for (const Vec3f exit : {Vec3f{0.3f, 1.0f, 0.3f}, Vec3f{1.0f, 1.0f, 1.0f}, Vec3f{-0.4f, 1.0f, -0.4f}}) {
    for (const float t : {0.3f, 0.6f, 0.9f}) {
      const Vec3f p = exit - d * t;
      if (std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}) >= 0.999f) continue;
      points.push_back(p);
      expected.push_back(1);
    }
  }
  std::vector<uint8_t> inside(points.size());
  ASSERT_TRUE(engine->occupancy(points, inside, {}).ok());
  for (std::size_t i = 0; i < points.size(); ++i)
    EXPECT_EQ(inside[i], expected[i])
        << "point " << i << " (" << points[i].x << ", " << points[i].y << ", " << points[i].z << ")";
}

TEST(OccupancyQuery, InsideAndOutsideClosedMeshes) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=4"}, 128);
  const auto engine = open_test_engine(*scene, "bvh", uint64_t{2} << 20);
  std::vector<Vec3f> points;
  std::vector<uint8_t> expected;
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<float> u(-1.5f, 1.5f);
  while (points.size() < 600) {
    const Vec3f p{u(rng), u(rng), u(rng)};
    const float r = length(p);
    if (r > 0.95f && r < 1.05f) continue;  // between the icosphere's faces and its vertices
    points.push_back(p);
    expected.push_back(r < 1.0f);
  }
  std::vector<uint8_t> inside(points.size());
  ASSERT_TRUE(engine->occupancy(points, inside, {}).ok());
  EXPECT_EQ(inside, expected);
}

TEST(OccupancyQuery, ParityIsNotTrustedOnEdgesOrAtTheOrigin) {
  auto record = [](float t, float u, float v) { return RayHitRecord{0, Hit{t, 0, 0, u, v, {}}}; };
  const std::vector<RayHitRecord> clean = {record(1, 0.3f, 0.3f)};
  EXPECT_TRUE(parity_of(clean).trusted);
  EXPECT_TRUE(parity_of(clean).odd);
  EXPECT_FALSE(parity_of(std::vector{record(1, 0.0f, 0.3f)}).trusted);
  EXPECT_FALSE(parity_of(std::vector{record(1, 0.3f, 0.0f)}).trusted);
  EXPECT_FALSE(parity_of(std::vector{record(1, 0.5f, 0.5f)}).trusted);
  EXPECT_FALSE(parity_of(std::vector{record(0, 0.3f, 0.3f)}).trusted);
  EXPECT_FALSE(parity_of({}).odd);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
