// Rays that enter no brick (RayWalk::start): answered at their first upper
// walk, never queued. On a sparse scene whose box is partly the surface of a
// closed cube (its walls lie on the scene box's faces) and partly two far
// spheres, rays outside the box, between the bricks, grazing the box's faces,
// edges and corners, starting inside it, with tnear > 0 or a short tfar are
// answered as the float64 brute force does, exactly (the "reference" brick
// structure is that computation behind the upper walk: a ray the walk drops
// would be a miss where the brute force hits), by every strategy and upper
// walk, closest and any hit; and rays_entering_no_brick counts the rays
// whose segment misses every brick's box (checked in float64 against the
// store's brick boxes).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/accel/brute_force_reference.h"
#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// The cube [0, 2]^3 as a closed shell, each face a 16 x 16 grid of quads
// (coordinates multiples of 1/8: exact, so edges are shared bitwise).
std::string cube_shell_obj() {
  constexpr int kCells = 16;
  std::string obj;
  int vertices = 0;
  char line[128];
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      const int base = vertices;
      for (int i = 0; i <= kCells; ++i) {
        for (int j = 0; j <= kCells; ++j) {
          float p[3];
          p[axis] = 2.0f * side;
          p[(axis + 1) % 3] = 2.0f * i / kCells;
          p[(axis + 2) % 3] = 2.0f * j / kCells;
          std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", p[0], p[1], p[2]);
          obj += line;
          ++vertices;
        }
      }
      for (int i = 0; i < kCells; ++i) {
        for (int j = 0; j < kCells; ++j) {
          const int a = base + i * (kCells + 1) + j + 1;  // OBJ indices start at 1
          std::snprintf(line, sizeof line, "f %d %d %d\nf %d %d %d\n", a, a + kCells + 1, a + kCells + 2, a,
                        a + kCells + 2, a + 1);
          obj += line;
        }
      }
    }
  }
  return obj;
}

// The scene: the cube shell and two small spheres far from it, so that the
// scene's box is [0, 6.3] x [0, 2] x [-5.3, 2]: its faces x = 0, y = 0,
// y = 2 and z = 2 are cube walls, and most of it is empty.
struct SparseScene {
  testing::TempDir dir;
  std::unique_ptr<testing::PackedScene> packed;
};

std::unique_ptr<SparseScene> sparse_scene(uint32_t brick_triangles) {
  auto scene = std::make_unique<SparseScene>();
  const std::string cube = scene->dir.file("cube.obj");
  testing::write_text_file(cube, cube_shell_obj());
  scene->packed = testing::pack_test_scene(
      {cube, "gen:sphere?level=2&radius=0.3&cx=6&cy=1&cz=1", "gen:sphere?level=2&radius=0.3&cx=1&cy=1&cz=-5"},
      brick_triangles);
  return scene;
}

Vec3f normalized(const Vec3f& v) {
  return v * (1.0f / std::sqrt(dot(v, v)));
}

struct TestRays {
  std::vector<Ray> rays;

  void add(const Ray& ray) { rays.push_back(ray); }
  // Eight rays from `origin` towards `target` and targets up to `spread`
  // from it: one direction octant, so the first pass walks them as a packet.
  void add_packet(const Vec3f& origin, const Vec3f& target, float spread, std::mt19937& rng,
                  float tnear = 0.0f, float tfar = INFINITY) {
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int k = 0; k < 8; ++k) {
      Ray r;
      r.origin = origin;
      r.direction = target + Vec3f(u(rng), u(rng), u(rng)) * spread - origin;
      r.tnear = tnear;
      r.tfar = tfar;
      add(r);
    }
  }
};

TestRays test_rays() {
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  TestRays t;
  const Vec3f center(3.15f, 1.0f, -1.65f);
  // Outside the scene's box, leaving it (from beyond its bounding sphere,
  // pointing away), alone and in packets.
  for (int i = 0; i < 200; ++i) {
    const Vec3f away = normalized(Vec3f(u01(rng) - 0.5f, u01(rng) - 0.5f, u01(rng) - 0.5f));
    Ray r;
    r.origin = center + away * 20.0f;
    r.direction = away + Vec3f(u01(rng), u01(rng), u01(rng)) * 0.1f;
    t.add(r);
  }
  for (int i = 0; i < 10; ++i) t.add_packet({-10.0f, 1.0f, 1.0f}, {-20.0f, 3.0f, 2.0f}, 1.0f, rng);
  // Along a face one float step outside it, leaving it by 1e-30 a unit (a
  // miss), and in its plane (through the edge of the wall across: the brute
  // force hits that edge).
  for (int i = 0; i < 50; ++i) {
    const float z = 0.05f + 1.9f * u01(rng);
    t.add({{-1.0f, std::nextafter(2.0f, 3.0f), z}, {1.0f, 1e-30f, 0.0f}});
    t.add({{-1.0f, 2.0f, z}, {1.0f, 0.0f, 0.0f}});
    t.add({{std::nextafter(0.0f, -1.0f), 0.5f + u01(rng), z}, {-1e-30f, 0.0f, -1.0f}});
  }
  // Into the box between its bricks: along z through the gap x in [2.5, 5.5]
  // between the cube and the far sphere, alone and in packets.
  for (int i = 0; i < 200; ++i) {
    Ray r;
    r.origin = {2.5f + 3.0f * u01(rng), 0.2f + 1.6f * u01(rng), 8.0f};
    r.direction = {0.01f * (u01(rng) - 0.5f), 0.01f * (u01(rng) - 0.5f), -1.0f};
    t.add(r);
  }
  for (int i = 0; i < 10; ++i) t.add_packet({4.0f, 1.0f, 8.0f}, {4.0f, 1.0f, -8.0f}, 0.3f, rng);
  // Grazing the box: through points of the cube's edges and corners that lie
  // on the scene box's edges, at shallow angles, and onto its walls nearly
  // along them. Each hits or misses as the brute force says.
  for (int i = 0; i < 300; ++i) {
    const float s = 2.0f * u01(rng);
    const Vec3f targets[] = {{0.0f, 2.0f, s}, {s, 2.0f, 2.0f},    {0.0f, 0.0f, s},
                             {0.0f, s, 2.0f}, {0.0f, 2.0f, 2.0f}, {s, 0.0f, 2.0f}};
    const Vec3f& target = targets[i % 6];
    const float tilt = std::ldexp(1.0f, -(i % 20));  // 1 down to 2^-19
    const Vec3f outward(target.x == 0.0f ? -1.0f : 0.0f,
                        target.y == 2.0f ? 1.0f : (target.y == 0.0f ? -1.0f : 0.0f),
                        target.z == 2.0f ? 1.0f : 0.0f);
    Ray r;
    r.origin = target + outward * tilt + Vec3f(1.0f, 0.0f, -1.0f) * (i % 2 == 0 ? 1.0f : -1.0f);
    r.direction = target - r.origin;
    t.add(r);
    if (i % 3 == 0) t.add_packet(r.origin, target, i % 2 == 0 ? 0.0f : 1e-3f, rng);
  }
  // Starting inside the box (inside the cube): unlimited they hit a wall; with
  // tfar short of every wall they enter no brick; a segment ending exactly at
  // a wall (t = tfar counts) hits it.
  for (int i = 0; i < 200; ++i) {
    Ray r;
    r.origin = {0.5f + u01(rng), 0.5f + u01(rng), 0.5f + u01(rng)};
    r.direction = normalized(Vec3f(u01(rng) - 0.5f, u01(rng) - 0.5f, u01(rng) - 0.5f));
    t.add(r);
    r.tfar = 0.4f;
    t.add(r);
    Ray to_wall;
    to_wall.origin = {r.origin.x, 1.0f + float(i % 64) / 64.0f, r.origin.z};
    to_wall.direction = {0.0f, 1.0f, 0.0f};
    to_wall.tfar = 2.0f - to_wall.origin.y;  // exactly the distance to the top wall
    t.add(to_wall);
  }
  t.add_packet({1.0f, 1.0f, 1.0f}, {1.0f, 1.0f, 1.5f}, 0.05f, rng, 0.0f, 0.4f);
  t.add_packet({1.0f, 1.0f, 1.0f}, {1.0f, 1.0f, 1.5f}, 0.05f, rng);
  // tnear > 0: from outside through the cube, the segment starting inside it
  // (hits the far wall) or beyond the scene's box (enters no brick).
  for (int i = 0; i < 100; ++i) {
    Ray r;
    r.origin = {-3.0f, 0.3f + 1.4f * u01(rng), 0.3f + 1.4f * u01(rng)};
    r.direction = {1.0f, 0.01f * (u01(rng) - 0.5f), 0.01f * (u01(rng) - 0.5f)};
    r.tnear = 4.0f;
    t.add(r);
    r.tnear = 12.0f;
    t.add(r);
  }
  t.add_packet({-3.0f, 1.0f, 1.0f}, {3.0f, 1.0f, 1.0f}, 0.05f, rng, 3.0f);  // starts at x = 15
  // Invalid rays between valid ones (a packet with holes): misses, not counted.
  Ray invalid;
  invalid.direction = {0.0f, 0.0f, 0.0f};
  for (int k = 0; k < 8; ++k) {
    if (k % 3 == 1) {
      t.add(invalid);
    } else {
      t.add({{-10.0f, 1.0f, 1.0f}, {-1.0f, 0.1f * k + 0.05f, 0.01f}});
    }
  }
  return t;
}

// Whether the segment of `ray` touches `box` grown by `margin` on every side,
// in float64, judged as the walks' slab test judges it: a zero direction
// component constrains nothing (the test widens the infinite distances it
// gives into NaN, which it ignores), so a ray parallel to a slab and outside
// it still enters the box's other slabs' range.
bool segment_touches(const Ray& ray, const Aabb& box, double margin) {
  double near = ray.tnear, far = ray.tfar;
  for (int axis = 0; axis < 3; ++axis) {
    const double o = ray.origin[axis], d = ray.direction[axis];
    if (d == 0.0) continue;
    const double t0 = (box.lo[axis] - margin - o) / d, t1 = (box.hi[axis] + margin - o) / d;
    near = std::max(near, std::min(t0, t1));
    far = std::min(far, std::max(t0, t1));
  }
  return near <= far;
}

// How many valid rays surely enter no brick (their segment misses every
// brick's box grown by a margin) and how many surely enter one (touch a box).
struct BrickEntry {
  uint64_t none = 0;
  uint64_t some = 0;
};

BrickEntry brick_entry(const QueryEngine& engine, const std::vector<Ray>& rays) {
  BrickEntry entry;
  for (const Ray& ray : rays) {
    if (!ray_is_valid(ray)) continue;
    bool any_touch = false, any_near = false;
    for (const BrickRecord& brick : engine.store().manifest().bricks) {
      any_touch |= segment_touches(ray, brick.bounds, 0.0);
      any_near |= segment_touches(ray, brick.bounds, 1e-3);
    }
    entry.none += !any_near;
    entry.some += any_touch;
  }
  return entry;
}

// Every answer as the brute force gives it, exactly.
void expect_reference_answers(const testing::PackedScene& scene, const std::vector<Ray>& rays,
                              const std::vector<Hit>& hits, const std::vector<uint8_t>& occluded,
                              const std::string& what) {
  uint64_t hit_count = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const ReferenceHit ref = reference_closest_hit(scene.triangles, scene.ids, rays[i]);
    const Hit& h = hits[i];
    ASSERT_EQ(h.is_hit(), ref.is_hit()) << what << " ray " << i;
    EXPECT_EQ(occluded[i] != 0, reference_any_hit(scene.triangles, rays[i])) << what << " ray " << i;
    if (!ref.is_hit()) continue;
    ++hit_count;
    EXPECT_EQ(h.geometry_id, ref.geometry_id) << what << " ray " << i;
    EXPECT_EQ(h.primitive_id, ref.primitive_id) << what << " ray " << i;
    EXPECT_EQ(h.t, static_cast<float>(ref.t)) << what << " ray " << i;
  }
  EXPECT_GT(hit_count, rays.size() / 4) << what << ": the test rays should hit often";
}

struct Run {
  const char* name;
  QueryOptions options;
  bool small_budget = false;
};

std::vector<Run> runs() {
  std::vector<Run> all;
  all.push_back({"default", {}});
  QueryOptions queued;
  queued.in_cache_sweep = false;
  all.push_back({"queued", queued});
  QueryOptions sse = queued;
  sse.avx_upper = false;
  all.push_back({"queued 4-wide", sse});
  QueryOptions sequential;
  sequential.reorder = false;
  all.push_back({"sequential", sequential});
  all.push_back({"queued, a budget of three bricks", {}, true});
  return all;
}

// The sparse scene packed with at most `brick_triangles` a brick into
// between min_bricks and max_bricks bricks, every test ray traced by every run.
void check_scene(uint32_t brick_triangles, uint32_t min_bricks, uint32_t max_bricks) {
  const auto scene = sparse_scene(brick_triangles);
  const testing::PackedScene& packed = *scene->packed;
  ASSERT_EQ(packed.bounds.lo, Vec3f(0.0f, 0.0f, packed.bounds.lo.z));
  ASSERT_EQ(packed.bounds.hi.y, 2.0f);
  ASSERT_EQ(packed.bounds.hi.z, 2.0f);
  const TestRays t = test_rays();
  uint64_t valid = 0;
  for (const Ray& ray : t.rays) valid += ray_is_valid(ray);
  for (const Run& run : runs()) {
    const std::string what = std::to_string(brick_triangles) + " triangles a brick, " + run.name;
    EngineOptions engine_options;
    engine_options.brick_accel = "reference";
    auto opened = QueryEngine::open(packed.path, engine_options);
    ASSERT_TRUE(opened.ok()) << opened.status().to_string();
    std::unique_ptr<QueryEngine> engine = std::move(opened).value();
    ASSERT_GE(engine->store().brick_count(), min_bricks);
    ASSERT_LE(engine->store().brick_count(), max_bricks);
    if (run.small_budget) {
      uint64_t most = 0;
      for (const BrickRecord& b : engine->store().manifest().bricks)
        most = std::max(most, engine->cache().builder().reserve_bytes(b.triangle_count));
      engine_options.cache_bytes = 3 * most;
      engine = std::move(QueryEngine::open(packed.path, engine_options)).value();
    }
    std::vector<Hit> hits(t.rays.size());
    std::vector<uint8_t> occluded(t.rays.size());
    const BrickEntry entry = brick_entry(*engine, t.rays);
    EXPECT_GT(entry.none, t.rays.size() / 4) << what << ": many test rays should enter no brick";
    EXPECT_GE(entry.none + entry.some, valid - valid / 10) << what << ": few rays in doubt (grazing ones)";
    QueryStats closest, any;
    // Twice: a cold batch (bricks built as needed), then a warm one.
    for (int pass = 0; pass < 2; ++pass) {
      ASSERT_TRUE(engine->intersect(t.rays, hits, run.options, &closest).ok()) << what;
      ASSERT_TRUE(engine->occluded(t.rays, occluded, run.options, &any).ok()) << what;
      expect_reference_answers(packed, t.rays, hits, occluded, what + " pass " + std::to_string(pass));
      for (const QueryStats& stats : {closest, any}) {
        EXPECT_GE(stats.rays_entering_no_brick, entry.none) << what;
        EXPECT_LE(stats.rays_entering_no_brick, valid - entry.some) << what;
      }
      EXPECT_EQ(closest.rays_entering_no_brick, any.rays_entering_no_brick) << what;
      EXPECT_EQ(closest.invalid_rays, 3u) << what;
    }
  }
}

TEST(RaysEnteringNoBrick, ManyBricksQueuedAnswerAsTheBruteForceAndAreCounted) {
  check_scene(128, 17, 1000);  // the queues by default, 4- and 8-wide walks, packets
}

TEST(RaysEnteringNoBrick, SomeBricksSweptAnswerAsTheBruteForceAndAreCounted) {
  check_scene(300, 9, 16);  // the in-cache sweep by default, not the flat walk
}

TEST(RaysEnteringNoBrick, FewBricksFlatAnswerAsTheBruteForceAndAreCounted) {
  check_scene(1024, 2, 8);  // the flat walk
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
