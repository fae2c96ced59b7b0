#include "core/ray/spawn_origin.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 1500;
#else
constexpr std::size_t kRays = 12000;
#endif

struct Config {
  std::string name;
  std::string brick_accel;
  BrickAccelOptions options;
  bool watertight;
};

const std::vector<Config>& configs() {
  static const std::vector<Config> all = {
      {"embree", "embree", {}, false},
      {"embree-robust", "embree", {{"robust", "1"}}, false},
      {"bvh-mt", "bvh", {{"triangle_test", "mt"}}, false},
      {"bvh-watertight", "bvh", {{"triangle_test", "watertight"}}, true},
      {"bvh-double", "bvh", {{"triangle_test", "double"}}, true},
  };
  return all;
}

std::unique_ptr<QueryEngine> open_engine(const std::string& path, const Config& config) {
  EngineOptions options;
  options.brick_accel = config.brick_accel;
  options.accel_options = config.options;
  auto engine = QueryEngine::open(path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  return engine.ok() ? std::move(engine).value() : nullptr;
}

std::vector<Hit> trace(QueryEngine& engine, const std::vector<Ray>& rays) {
  std::vector<Hit> hits(rays.size());
  const Status status = engine.intersect(rays, hits, QueryOptions{});
  EXPECT_TRUE(status.ok()) << status.to_string();
  return hits;
}

Vec3f unit_random(std::mt19937_64& rng) {
  std::normal_distribution<float> g;
  for (;;) {
    const Vec3f v(g(rng), g(rng), g(rng));
    if (length(v) > 1e-3f) return normalize(v);
  }
}

// Primary rays from a sphere around (centre, radius) aimed at points inside it.
std::vector<Ray> primary_rays(const Vec3f& centre, float radius, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Ray> rays(n);
  for (auto& ray : rays) {
    ray.origin = centre + unit_random(rng) * (3.0f * radius);
    ray.direction = centre + unit_random(rng) * (0.7f * radius) - ray.origin;
  }
  return rays;
}

Vec3f reflect(const Vec3f& d, const Vec3f& n) {
  return d - n * (2.0f * dot(d, n));
}

TEST(SpawnOrigin, MissGivesNaNAndSidesAreOppositeAlongTheNormal) {
  Ray ray;
  ray.origin = {0, 0, 5};
  ray.direction = {0, 0, -1};
  Hit miss;
  const Vec3f none = spawn_origin(ray, miss, SpawnSide::kFront);
  EXPECT_TRUE(std::isnan(none.x) && std::isnan(none.y) && std::isnan(none.z));

  Hit hit;
  hit.t = 5.0f;
  hit.geometry_id = 0;
  hit.primitive_id = 0;
  hit.normal = {0, 0, 1};  // front face: the ray came from +z
  const Vec3f front = spawn_origin(ray, hit, SpawnSide::kFront);
  const Vec3f back = spawn_origin(ray, hit, SpawnSide::kBack);
  // delta = 2^-16 * (|o| + |p| + t |d|) = 2^-16 * (5 + 0 + 5), around the point (0, 0, 0).
  const double delta = std::ldexp(10.0, -16);
  EXPECT_EQ(front.x, 0.0f);
  EXPECT_EQ(front.y, 0.0f);
  EXPECT_EQ(front.z, static_cast<float>(delta));
  EXPECT_EQ(back.z, static_cast<float>(-delta));
  // A back-face hit (normal along the ray) puts the front on the other side.
  hit.normal = {0, 0, -1};
  EXPECT_EQ(spawn_origin(ray, hit, SpawnSide::kFront).z, static_cast<float>(delta));
}

// The offset scales with the magnitudes involved: far from the origin the
// point is still moved off the plane by many ulps.
TEST(SpawnOrigin, OffsetGrowsWithDistanceFromTheOrigin) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    Ray ray;
    ray.origin = {offset, offset, offset + 10.0f};
    ray.direction = {0, 0, -1};
    Hit hit;
    hit.t = 10.0f;
    hit.geometry_id = hit.primitive_id = 0;
    hit.normal = {0, 0, 1};
    const Vec3f front = spawn_origin(ray, hit, SpawnSide::kFront);
    const float plane = offset;
    EXPECT_GT(front.z, plane);
    // At least 64 ulps of the coordinate, at most 1e-4 relative.
    EXPECT_GE(front.z - plane,
              64.0f * (std::nextafter(std::max(plane, 1.0f), INFINITY) - std::max(plane, 1.0f)));
    EXPECT_LE(front.z - plane, 1e-4f * (std::fabs(plane) + 10.0f));
  }
}

// Shadow and bounce rays from the front never re-hit their own triangle;
// transmission rays from the back never do either and, in a closed mesh with
// a watertight configuration, always hit something (the far side).
class SpawnOriginEngine : public ::testing::TestWithParam<std::size_t> {};

TEST_P(SpawnOriginEngine, SecondaryRaysNeverReHitTheirOwnTriangle) {
  const Config& config = configs()[GetParam()];
  struct Placement {
    std::string spec;
    Vec3f centre;
    float radius;
  };
  const std::vector<Placement> scenes = {
      {"gen:sphere?level=4", {0, 0, 0}, 1.0f},
      {"gen:sphere?level=4&radius=0.1&cx=1000&cy=-1000&cz=1000", {1000, -1000, 1000}, 0.1f},
      {"gen:torus?major=1e6&minor=3e5&cx=1e6", {1e6f, 0, 0}, 1.3e6f},
  };
  for (const auto& scene : scenes) {
    SCOPED_TRACE(config.name + " on " + scene.spec);
    const auto packed = testing::pack_test_scene({scene.spec}, 512);
    auto engine = open_engine(packed->path, config);
    ASSERT_NE(engine, nullptr);
    const auto rays = primary_rays(scene.centre, scene.radius, kRays, 7);
    const auto hits = trace(*engine, rays);

    std::mt19937_64 rng(11);
    std::vector<Ray> shadow, bounce, through;
    std::vector<std::size_t> from;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (!hits[i].is_hit()) continue;
      from.push_back(i);
      const Vec3f d = rays[i].direction;
      const Vec3f n = hits[i].normal;
      const Vec3f front_normal = dot(d, n) < 0 ? n : -n;
      Ray s;
      s.origin = spawn_origin(rays[i], hits[i], SpawnSide::kFront);
      // A light somewhere on the front side, at a distance like the scene's.
      Vec3f to_light = unit_random(rng);
      if (dot(to_light, front_normal) < 0) to_light = -to_light;
      s.direction = to_light * scene.radius;
      shadow.push_back(s);
      Ray b = s;
      b.direction = reflect(d, n);
      bounce.push_back(b);
      Ray t;
      t.origin = spawn_origin(rays[i], hits[i], SpawnSide::kBack);
      t.direction = d;
      through.push_back(t);
    }
    ASSERT_GT(from.size(), kRays / 4);
    const auto shadow_hits = trace(*engine, shadow);
    const auto bounce_hits = trace(*engine, bounce);
    const auto through_hits = trace(*engine, through);
    std::size_t self = 0, leaks = 0;
    for (std::size_t k = 0; k < from.size(); ++k) {
      const Hit& h = hits[from[k]];
      for (const Hit* next : {&shadow_hits[k], &bounce_hits[k], &through_hits[k]}) {
        if (next->is_hit() && next->geometry_id == h.geometry_id && next->primitive_id == h.primitive_id)
          ++self;
      }
      if (!through_hits[k].is_hit()) ++leaks;
    }
    EXPECT_EQ(self, 0u) << "secondary rays re-hit their own triangle";
    // Closed meshes: a ray continuing through the surface must hit the far side.
    if (config.watertight) {
      EXPECT_EQ(leaks, 0u) << "transmission rays escaped the closed mesh";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Configs, SpawnOriginEngine, ::testing::Range<std::size_t>(0, 5),
                         [](const auto& info) {
                           std::string name = configs()[info.param].name;
                           for (char& c : name) c = c == '-' ? '_' : c;
                           return name;
                         });

// A neighbour a little farther than the offset is never skipped: a floor and a
// parallel ceiling at height h (a thin gap, as in a layered or folded mesh),
// at several offsets from the origin; rays hit the floor, the spawned rays go
// straight up and must hit the ceiling at about h.
TEST_P(SpawnOriginEngine, NearNeighbourIsNotSkipped) {
  const Config& config = configs()[GetParam()];
  for (const double where : {0.0, 1e3, 1e6}) {
    for (const double relative_gap : {1e-3, 1e-4}) {
      // Relative to the coordinates: at 1e6 a float step is 0.0625.
      const double gap = relative_gap * (1.0 + where);
      SCOPED_TRACE(config.name + " at " + std::to_string(where) + " gap " + std::to_string(gap));
      TempDir dir;
      const std::string obj = dir.file("layers.obj");
      {
        // Square floor at z = where and ceiling at z = where + gap*size, size 1.
        FILE* f = std::fopen(obj.c_str(), "w");
        ASSERT_NE(f, nullptr);
        const double z0 = where, z1 = where + gap;
        for (const double z : {z0, z1}) {
          std::fprintf(f,
                       "v %.17g %.17g %.17g\nv %.17g %.17g %.17g\nv %.17g %.17g %.17g\nv %.17g %.17g %.17g\n",
                       where, where, z, where + 1, where, z, where + 1, where + 1, z, where, where + 1, z);
        }
        std::fprintf(f, "f 1 2 3\nf 1 3 4\nf 5 7 6\nf 5 8 7\n");
        std::fclose(f);
      }
      const auto packed = testing::pack_test_scene({obj}, 64);
      auto engine = open_engine(packed->path, config);
      ASSERT_NE(engine, nullptr);
      std::mt19937_64 rng(3);
      std::uniform_real_distribution<double> u(0.05, 0.95);
      std::vector<Ray> down(500);
      for (auto& ray : down) {
        // From inside the gap, slanted down onto the floor.
        const float fz = static_cast<float>(where + 0.5 * gap);
        ray.origin = {static_cast<float>(where + u(rng)), static_cast<float>(where + u(rng)), fz};
        // Sideways by at most 0.09: the ray stays above the unit square.
        ray.direction = {static_cast<float>(0.2 * (u(rng) - 0.5)), static_cast<float>(0.2 * (u(rng) - 0.5)),
                         static_cast<float>(-0.5 * gap)};
      }
      const auto hits = trace(*engine, down);
      std::vector<Ray> up;
      std::vector<std::size_t> from;
      for (std::size_t i = 0; i < down.size(); ++i) {
        if (!hits[i].is_hit() || hits[i].primitive_id > 1) continue;
        Ray r;
        r.origin = spawn_origin(down[i], hits[i], SpawnSide::kFront);
        r.direction = {0, 0, 1};
        up.push_back(r);
        from.push_back(i);
      }
      ASSERT_GT(up.size(), down.size() / 2);
      const auto up_hits = trace(*engine, up);
      std::size_t skipped = 0;
      for (std::size_t k = 0; k < up.size(); ++k) {
        if (!up_hits[k].is_hit() || up_hits[k].primitive_id < 2) ++skipped;
      }
      EXPECT_EQ(skipped, 0u) << "spawned rays missed the ceiling " << gap << " above";
    }
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
