#include "core/accel/embree_brick.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brute_force_reference.h"
#include "core/accel/embree_device.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using namespace accel_test;

constexpr float kInf = std::numeric_limits<float>::infinity();

// Ray counts for the brute-force comparisons: a quarter under sanitizers,
// where the float64 reference runs unoptimised.
#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t rays_for_reference(std::size_t n) {
  return n / 4;
}
#else
constexpr std::size_t rays_for_reference(std::size_t n) {
  return n;
}
#endif

std::vector<EmbreeBrickConfig> all_configs() {
  std::vector<EmbreeBrickConfig> out;
  for (bool robust : {false, true}) {
    for (EmbreeQuality q : {EmbreeQuality::kLow, EmbreeQuality::kMedium, EmbreeQuality::kHigh}) {
      out.push_back({robust, q});
    }
  }
  return out;
}

std::string describe(const EmbreeBrickConfig& c) {
  const char* q =
      c.quality == EmbreeQuality::kLow ? "low" : (c.quality == EmbreeQuality::kMedium ? "medium" : "high");
  return std::string("robust=") + (c.robust ? "1" : "0") + " quality=" + q;
}

std::unique_ptr<EmbreeBrickAccel> build_or_die(BrickData brick, const EmbreeBrickConfig& config = {}) {
  auto accel = EmbreeBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return accel.ok() ? std::move(accel).value() : nullptr;
}

std::vector<ReferenceHit> reference_hits(const BrickData& brick, const std::vector<Ray>& rays) {
  std::vector<ReferenceHit> out(rays.size());
  tbb::parallel_for(std::size_t{0}, rays.size(), [&](std::size_t i) {
    out[i] = reference_closest_hit(brick.triangles, brick.ids, rays[i]);
  });
  return out;
}

// Position of every id in the brick, to find the triangle a hit names.
std::unordered_map<uint64_t, uint32_t> index_of_ids(const BrickData& brick) {
  std::unordered_map<uint64_t, uint32_t> out;
  for (uint32_t k = 0; k < brick.ids.size(); ++k) {
    out[(uint64_t{brick.ids[k].geometry_id} << 32) | brick.ids[k].primitive_id] = k;
  }
  return out;
}

double min_barycentric(double u, double v) {
  return std::min({u, v, 1.0 - u - v});
}

// Compares hits with the float64 reference. Disagreements about which
// triangle (or whether any) is hit are allowed only where the reference says
// they are legitimate: a true tie in t (shared edge or vertex, |dt| <= 1e-6
// relative) or a ray within 1e-5 (barycentric) of a triangle's border; those
// are counted in `edge_cases`.
struct Comparison {
  int compared = 0;
  int hits = 0;
  int edge_cases = 0;
};

void expect_matches_reference(const BrickData& brick, const std::vector<Ray>& rays,
                              const std::vector<Hit>& got, const std::vector<ReferenceHit>& want,
                              Comparison& cmp, const std::string& label, double uv_tolerance) {
  const auto index = index_of_ids(brick);
  const auto triangle_of = [&](const Hit& h) -> const Triangle& {
    return brick.triangles[index.at((uint64_t{h.geometry_id} << 32) | h.primitive_id)];
  };
  int failures = 0;
  for (std::size_t i = 0; i < rays.size() && failures < 10; ++i) {
    const Hit& g = got[i];
    const ReferenceHit& w = want[i];
    ++cmp.compared;
    SCOPED_TRACE(label + " ray " + std::to_string(i));
    const int failures_before = ::testing::Test::HasFailure() ? 1 : 0;
    if (!g.is_hit()) {
      EXPECT_EQ(g.t, kInf);
      EXPECT_EQ(g.geometry_id, kInvalidId);
      EXPECT_EQ(g.primitive_id, kInvalidId);
      EXPECT_EQ(g.u, 0.0f);
      EXPECT_EQ(g.v, 0.0f);
      EXPECT_EQ(g.normal, Vec3f(0, 0, 0));
      if (w.is_hit()) {
        // Embree missed what the reference hit: only at a triangle's border.
        EXPECT_LT(min_barycentric(w.u, w.v), 1e-5) << "missed a clear hit at t=" << w.t;
        ++cmp.edge_cases;
      }
    } else {
      ++cmp.hits;
      const Triangle& tri = triangle_of(g);
      const auto plane = reference_plane_hit(tri, rays[i]);
      ASSERT_TRUE(plane.has_value());
      // Wherever Embree hit, the reference agrees on t and u, v for that triangle.
      EXPECT_NEAR(g.t, plane->t, 1e-5 * std::abs(plane->t)) << "t of the triangle Embree reports";
      EXPECT_NEAR(g.u, plane->u, uv_tolerance);
      EXPECT_NEAR(g.v, plane->v, uv_tolerance);
      EXPECT_GE(min_barycentric(plane->u, plane->v), -1e-5) << "hit outside its triangle";
      EXPECT_GT(double(g.t), double(rays[i].tnear));
      EXPECT_LE(g.t, rays[i].tfar);
      const Vec3d n(g.normal);
      EXPECT_NEAR(length(n), 1.0, 1e-6);
      const Vec3d ref_normal = reference_unit_normal(tri);
      EXPECT_LE(length(n - ref_normal), 1e-5);
      if (!w.is_hit()) {
        EXPECT_LT(min_barycentric(plane->u, plane->v), 1e-5) << "hit where the reference sees nothing";
        ++cmp.edge_cases;
      } else if (g.geometry_id != w.geometry_id || g.primitive_id != w.primitive_id) {
        // Another triangle: a true tie (shared edge/vertex), or the reference's
        // triangle hit only at its border.
        const bool tie = std::abs(plane->t - w.t) <= 1e-6 * std::abs(w.t);
        EXPECT_TRUE(tie || min_barycentric(w.u, w.v) < 1e-5)
            << "got (" << g.geometry_id << "," << g.primitive_id << ") t=" << g.t << ", reference ("
            << w.geometry_id << "," << w.primitive_id << ") t=" << w.t;
        ++cmp.edge_cases;
      } else {
        EXPECT_NEAR(g.t, w.t, 1e-5 * std::abs(w.t));
        EXPECT_NEAR(g.u, w.u, uv_tolerance);
        EXPECT_NEAR(g.v, w.v, uv_tolerance);
        EXPECT_LE(length(n - w.normal), 1e-5);
      }
    }
    if (::testing::Test::HasFailure() && !failures_before) ++failures;
  }
}

// Closest hit and any hit against the reference for every option combination.
void check_against_reference(const BrickData& brick, const std::vector<Ray>& rays, const std::string& label,
                             int max_edge_cases, double uv_tolerance = 1e-4) {
  const auto want = reference_hits(brick, rays);
  const auto ids = all_ids(rays.size());
  for (const auto& config : all_configs()) {
    const std::string where = label + " " + describe(config);
    const auto accel = build_or_die(brick, config);
    ASSERT_NE(accel, nullptr);
    std::vector<Hit> got(rays.size());
    accel->intersect(ids, rays.data(), got.data());
    Comparison cmp;
    expect_matches_reference(brick, rays, got, want, cmp, where, uv_tolerance);
    EXPECT_LE(cmp.edge_cases, max_edge_cases) << where;
    std::printf("%s: %d rays, %d hits, %d edge cases\n", where.c_str(), cmp.compared, cmp.hits,
                cmp.edge_cases);

    std::vector<uint8_t> occluded(rays.size(), 0);
    accel->occluded(ids, rays.data(), occluded.data());
    int disagreements = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if ((occluded[i] != 0) != want[i].is_hit()) ++disagreements;
      if ((occluded[i] != 0) != got[i].is_hit()) {
        // Any hit differs from closest hit only at a border.
        EXPECT_TRUE(want[i].is_hit() && min_barycentric(want[i].u, want[i].v) < 1e-5)
            << where << " ray " << i;
      }
    }
    EXPECT_LE(disagreements, max_edge_cases) << where;
  }
}

TEST(EmbreeBrick, NormalFollowsEmbreeNgSign) {
  // Counter-clockwise seen from +z.
  BrickData brick;
  brick.triangles = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  brick.ids = {{2, 5}};

  // Embree's own Ng for this triangle, straight from rtcIntersect1.
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  std::vector<float> vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0};
  std::vector<uint32_t> indices = {0, 1, 2, 0};
  RTCScene scene = rtcNewScene((*device)->handle());
  RTCGeometry geometry = rtcNewGeometry((*device)->handle(), RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices.data(), 0, 12,
                             3);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices.data(), 0, 12, 1);
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);

  const auto accel = build_or_die(brick);
  ASSERT_NE(accel, nullptr);
  for (const float dz : {-1.0f, 1.0f}) {  // from above and from below
    SCOPED_TRACE(dz);
    Ray ray;
    ray.origin = {0.25f, 0.5f, -2.0f * dz};
    ray.direction = {0, 0, dz};
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh{};
    rh.ray = {ray.origin.x, ray.origin.y, ray.origin.z, 0.0f, 0, 0, dz, 0.0f, kInf, 0xffffffffu, 0, 0};
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, &context, &rh);
    ASSERT_EQ(rh.hit.geomID, 0u);
    EXPECT_EQ(rh.hit.Ng_x, 0.0f);
    EXPECT_EQ(rh.hit.Ng_y, 0.0f);
    EXPECT_GT(rh.hit.Ng_z, 0.0f) << "Embree's Ng = cross(v1 - v0, v2 - v0), whatever side the ray comes from";

    Hit hit;
    const uint32_t id = 0;
    accel->intersect({&id, 1}, &ray, &hit);
    ASSERT_TRUE(hit.is_hit());
    EXPECT_EQ(hit.geometry_id, 2u);
    EXPECT_EQ(hit.primitive_id, 5u);
    // Embree's own t, bitwise; 2 only to within its reciprocal's rounding,
    // which depends on the kernel the CPU gets (exactly 2 on some, an ulp
    // off with AVX2's rcp and one Newton step).
    EXPECT_EQ(hit.t, rh.ray.tfar);
    EXPECT_FLOAT_EQ(hit.t, 2.0f);
    EXPECT_FLOAT_EQ(hit.u, 0.25f);
    EXPECT_FLOAT_EQ(hit.v, 0.5f);
    EXPECT_EQ(hit.normal, Vec3f(0, 0, 1));
  }
  rtcReleaseScene(scene);
}

TEST(EmbreeBrick, MatchesReferenceOnBunny) {
  const BrickData bunny = load_brick_from(bunny_path());
  ASSERT_EQ(bunny.triangles.size(), 69451u);
  const Aabb b = bounds_of(bunny);
  std::vector<Ray> rays = rays_from_outside(b, rays_for_reference(1500), 11);
  const auto inside = rays_from_inside(b, rays_for_reference(500), 12);
  rays.insert(rays.end(), inside.begin(), inside.end());
  check_against_reference(bunny, rays, "bunny", 4);
}

TEST(EmbreeBrick, MatchesReferenceOnSphere) {
  const BrickData sphere = load_brick_from("gen:sphere?level=5&radius=2&cx=1");
  ASSERT_EQ(sphere.triangles.size(), 20480u);
  const Aabb b = bounds_of(sphere);
  std::vector<Ray> rays = rays_from_outside(b, rays_for_reference(3000), 21);
  // From the centre outwards: every ray hits (closed mesh).
  auto inside = rays_from_inside(b, rays_for_reference(2000), 22);
  for (Ray& r : inside) r.origin = {1, 0, 0};
  rays.insert(rays.end(), inside.begin(), inside.end());
  check_against_reference(sphere, rays, "sphere", 4);
}

TEST(EmbreeBrick, DegenerateTrianglesAreNeverHit) {
  const BrickData brick = degenerate_heavy(4000, 5);
  auto accel = build_or_die(brick);
  ASSERT_NE(accel, nullptr);
  EXPECT_EQ(accel->triangle_count(), 4000u);
  EXPECT_LT(accel->scene_triangle_count(), 4000u);
  EXPECT_GE(accel->scene_triangle_count(), 2000u);
  check_against_reference(brick, rays_from_outside(bounds_of(brick), 3000, 31), "degenerate", 4);

  BrickData only_degenerate;
  only_degenerate.triangles = {{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, {{0, 0, 0}, {0, 0, 0}, {0, 1, 0}}};
  only_degenerate.ids = {{0, 0}, {0, 1}};
  accel = build_or_die(only_degenerate);
  ASSERT_NE(accel, nullptr);
  EXPECT_EQ(accel->scene_triangle_count(), 0u);
  Ray ray;
  ray.origin = {0, 0.0f, -1};
  ray.direction = {0, 0, 1};
  Hit hit;
  uint8_t blocked = 0;
  const uint32_t id = 0;
  accel->intersect({&id, 1}, &ray, &hit);
  accel->occluded({&id, 1}, &ray, &blocked);
  EXPECT_FALSE(hit.is_hit());
  EXPECT_EQ(blocked, 0);
}

TEST(EmbreeBrick, SegmentLimitsAreRespected) {
  const BrickData sphere = load_brick_from("gen:sphere?level=4");
  const auto rays = rays_from_outside(bounds_of(sphere), 400, 41);
  const auto first = reference_hits(sphere, rays);
  std::vector<Ray> cut;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (!first[i].is_hit()) continue;
    Ray before = rays[i];  // ends just short of the surface: misses
    before.tfar = static_cast<float>(first[i].t * 0.999);
    Ray beyond = rays[i];  // starts just past it: the far side of the sphere
    beyond.tnear = static_cast<float>(first[i].t * 1.001);
    Ray window = rays[i];  // a window around it: hits
    window.tnear = static_cast<float>(first[i].t * 0.99);
    window.tfar = static_cast<float>(first[i].t * 1.01);
    cut.insert(cut.end(), {before, beyond, window});
  }
  ASSERT_GT(cut.size(), 300u);
  const auto want = reference_hits(sphere, cut);
  for (std::size_t i = 0; i < cut.size(); i += 3) {
    EXPECT_FALSE(want[i].is_hit());
    EXPECT_TRUE(want[i + 1].is_hit());
    EXPECT_TRUE(want[i + 2].is_hit());
  }
  check_against_reference(sphere, cut, "segments", 4);
}

// A triangle present in several bricks (duplicates across bricks) under
// different ids: whatever the order the bricks are traced in, the smaller
// (geometry_id, primitive_id) wins, with bitwise equal t.
TEST(EmbreeBrick, TiesAcrossBricksFollowTheTieRule) {
  const Triangle tri{{-1, -1, 3}, {2, -1, 3.5f}, {-1, 2, 2.5f}};
  const std::array<TriangleId, 3> ids = {TriangleId{0, 7}, TriangleId{0, 3}, TriangleId{1, 0}};
  std::vector<std::unique_ptr<EmbreeBrickAccel>> bricks;
  for (const TriangleId& id : ids) {
    BrickData b;
    b.triangles = {tri};
    b.ids = {id};
    bricks.push_back(build_or_die(std::move(b)));
    ASSERT_NE(bricks.back(), nullptr);
  }
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-0.9f, 0.4f);
  std::vector<Ray> rays(2000);
  for (Ray& r : rays) {
    r.origin = {u(rng) * 0.1f, u(rng) * 0.1f, -1.0f};
    r.direction = Vec3f(Vec3d(u(rng), u(rng), 3.0) - Vec3d(r.origin));
  }
  const auto all = all_ids(rays.size());
  std::array<int, 3> order = {0, 1, 2};
  std::vector<Hit> first;
  do {
    std::vector<Hit> hits(rays.size());
    for (int b : order) bricks[b]->intersect(all, rays.data(), hits.data());
    for (const Hit& h : hits) {
      ASSERT_TRUE(h.is_hit());
      EXPECT_EQ(h.geometry_id, 0u);
      EXPECT_EQ(h.primitive_id, 3u);
    }
    if (first.empty()) {
      first = hits;
    } else {
      for (std::size_t i = 0; i < hits.size(); ++i) EXPECT_EQ(hits[i].t, first[i].t);
    }
  } while (std::next_permutation(order.begin(), order.end()));

  // Preset hits at exactly that t: a larger id is replaced, a smaller one kept;
  // a nearer hit is never replaced.
  std::vector<Hit> larger = first, smaller = first, nearer = first;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    larger[i].primitive_id = 4;
    smaller[i].primitive_id = 2;
    nearer[i].t = std::nextafter(first[i].t, 0.0f);
    nearer[i].primitive_id = 9;
  }
  bricks[1]->intersect(all, rays.data(), larger.data());
  bricks[1]->intersect(all, rays.data(), smaller.data());
  bricks[1]->intersect(all, rays.data(), nearer.data());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    EXPECT_EQ(larger[i].primitive_id, 3u);
    EXPECT_EQ(larger[i].t, first[i].t);
    EXPECT_EQ(smaller[i].primitive_id, 2u);
    EXPECT_EQ(nearer[i].primitive_id, 9u);
  }
}

// Pinhole-camera rays over `coverage` times the box's width, in 16x16 tiles
// (one chunk of the accel each): coherent chunks, traced as Embree streams.
std::vector<Ray> camera_rays(const Aabb& b, int size, float coverage) {
  const Vec3f c = b.center();
  const Vec3f e = b.extent();
  const Vec3f eye = c + Vec3f(0.3f * e.x, 0.2f * e.y, 2.5f * e.z + 1.5f * e.x);
  std::vector<Ray> rays;
  for (int ty = 0; ty < size; ty += 16) {
    for (int tx = 0; tx < size; tx += 16) {
      for (int y = ty; y < ty + 16; ++y) {
        for (int x = tx; x < tx + 16; ++x) {
          const Vec3f target = c + Vec3f((x / float(size) - 0.5f) * coverage * e.x,
                                         (y / float(size) - 0.5f) * coverage * e.y, 0);
          Ray r;
          r.origin = eye;
          r.direction = target - eye;
          rays.push_back(r);
        }
      }
    }
  }
  return rays;
}

// Every ray traced alone (chunks of one: never a coherent stream).
void trace_one_by_one(const EmbreeBrickAccel& accel, const std::vector<Ray>& rays, std::vector<Hit>& hits,
                      std::vector<uint8_t>& occluded) {
  for (uint32_t i = 0; i < rays.size(); ++i) {
    accel.intersect({&i, 1}, rays.data(), hits.data());
    accel.occluded({&i, 1}, rays.data(), occluded.data());
  }
}

TEST(EmbreeBrick, CoherentStreamsMatchReferenceAndSingleRays) {
  const BrickData bunny = load_brick_from(bunny_path());
  const auto rays = camera_rays(bounds_of(bunny), rays_for_reference(48 * 48) == 48 * 48 ? 48 : 32, 0.6f);
  // Rays from afar: Embree's float u, v lose accuracy in proportion to the
  // distance over the triangle's size (here about 300), hence 5e-4.
  check_against_reference(bunny, rays, "bunny camera", 4, 5e-4);
  for (const auto& config : all_configs()) {
    SCOPED_TRACE(describe(config));
    const auto accel = build_or_die(bunny, config);
    ASSERT_NE(accel, nullptr);
    std::vector<Hit> batch(rays.size()), single(rays.size());
    std::vector<uint8_t> batch_occluded(rays.size()), single_occluded(rays.size());
    accel->intersect(all_ids(rays.size()), rays.data(), batch.data());
    accel->occluded(all_ids(rays.size()), rays.data(), batch_occluded.data());
    // Tiles whose rays straddle a direction octant are not coherent; the
    // others are, for closest and any hit alike.
    const uint64_t coherent = accel->coherent_rays();
    EXPECT_GE(coherent, rays.size()) << "camera tiles should mostly go as coherent streams";
    trace_one_by_one(*accel, rays, single, single_occluded);
    EXPECT_EQ(accel->coherent_rays(), coherent) << "single rays never do";
    EXPECT_EQ(std::memcmp(batch.data(), single.data(), batch.size() * sizeof(Hit)), 0);
    EXPECT_EQ(batch_occluded, single_occluded);
  }
}

// Each triangle twice, under (0, k) and (1, k): at bitwise equal t inside one
// brick the tie filter picks geometry 0 (the smaller id), on either path
// (coherent stream or single ray), from any side, whatever the build (rebuilt,
// and built under 1 or 4 threads).
TEST(EmbreeBrick, DuplicatesInsideABrickFollowTheTieRuleWhateverThePathOrBuild) {
  const BrickData sphere = load_brick_from("gen:sphere?level=4");
  BrickData doubled;
  for (uint32_t k = 0; k < sphere.triangles.size(); ++k) {
    // Interleaved both ways, so neither copy is always first in memory.
    const bool flip = k % 2 == 1;
    doubled.triangles.insert(doubled.triangles.end(), {sphere.triangles[k], sphere.triangles[k]});
    doubled.ids.push_back({flip ? 1u : 0u, k});
    doubled.ids.push_back({flip ? 0u : 1u, k});
  }
  const Aabb b = bounds_of(doubled);
  std::vector<Ray> rays = camera_rays(b, 64, 1.2f);
  const auto outside = rays_from_outside(b, 2000, 81);
  rays.insert(rays.end(), outside.begin(), outside.end());
  const auto accel = build_or_die(doubled);
  ASSERT_NE(accel, nullptr);
  std::vector<Hit> batch(rays.size()), single(rays.size());
  std::vector<uint8_t> occluded_batch(rays.size()), occluded_single(rays.size());
  accel->intersect(all_ids(rays.size()), rays.data(), batch.data());
  EXPECT_GT(accel->coherent_rays(), 0u) << "the camera tiles should go as coherent streams";
  trace_one_by_one(*accel, rays, single, occluded_single);
  int hits = 0;
  std::array<int, 2> picked = {0, 0};
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (!batch[i].is_hit()) continue;
    ++hits;
    ++picked[batch[i].geometry_id & 1];
    EXPECT_EQ(batch[i].geometry_id, 0u) << "ray " << i;
    EXPECT_EQ(std::memcmp(&batch[i], &single[i], sizeof(Hit)), 0) << "ray " << i;
  }
  EXPECT_GT(hits, 2000);
  std::printf("duplicates: %d hits, geometry 0 picked %d times, geometry 1 %d times\n", hits, picked[0],
              picked[1]);
  for (const int threads : {1, 4}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const auto rebuilt = build_or_die(doubled);
    ASSERT_NE(rebuilt, nullptr);
    std::vector<Hit> again(rays.size());
    rebuilt->intersect(all_ids(rays.size()), rays.data(), again.data());
    EXPECT_EQ(std::memcmp(again.data(), batch.data(), batch.size() * sizeof(Hit)), 0)
        << threads << " threads";
  }
}

TEST(EmbreeBrick, OccludedSkipsRaysAlreadyBlockedAndKeepsFlags) {
  const BrickData sphere = load_brick_from("gen:sphere?level=3");
  const auto accel = build_or_die(sphere);
  ASSERT_NE(accel, nullptr);
  Ray hit_ray, miss_ray;
  hit_ray.origin = miss_ray.origin = {0, 0, -5};
  hit_ray.direction = {0, 0, 1};
  miss_ray.direction = {0, 1, 0};
  const std::vector<Ray> rays = {hit_ray, miss_ray, miss_ray};
  std::vector<uint8_t> occluded = {0, 0, 1};  // ray 2 was blocked by another brick
  const auto ids = all_ids(3);
  accel->occluded(ids, rays.data(), occluded.data());
  EXPECT_EQ(occluded, (std::vector<uint8_t>{1, 0, 1}));
}

TEST(EmbreeBrick, ConcurrentIntersectMatchesSerial) {
  const BrickData bunny = load_brick_from(bunny_path());
  const auto accel = build_or_die(bunny);
  ASSERT_NE(accel, nullptr);
  const auto rays = rays_from_outside(bounds_of(bunny), 100000, 51);
  std::vector<Hit> serial(rays.size()), parallel(rays.size());
  accel->intersect(all_ids(rays.size()), rays.data(), serial.data());
  std::vector<uint8_t> occluded_serial(rays.size()), occluded_parallel(rays.size());
  accel->occluded(all_ids(rays.size()), rays.data(), occluded_serial.data());

  constexpr int kThreads = 4;
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::vector<uint32_t> mine;  // interleaved: disjoint, and neighbours on different threads
      for (uint32_t i = t; i < rays.size(); i += kThreads) mine.push_back(i);
      accel->intersect(mine, rays.data(), parallel.data());
      accel->occluded(mine, rays.data(), occluded_parallel.data());
    });
  }
  for (auto& th : threads) th.join();
  for (std::size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(std::memcmp(&serial[i], &parallel[i], sizeof(Hit)), 0) << "ray " << i;
  }
  EXPECT_EQ(occluded_serial, occluded_parallel);
}

TEST(EmbreeBrick, EmptyAndMalformedBricks) {
  auto empty = EmbreeBrickAccel::build(BrickData{}, {});
  ASSERT_TRUE(empty.ok()) << empty.status().to_string();
  EXPECT_EQ((*empty)->triangle_count(), 0u);
  Ray ray;
  ray.direction = {0, 0, 1};
  Hit hit;
  const uint32_t id = 0;
  (*empty)->intersect({&id, 1}, &ray, &hit);
  EXPECT_FALSE(hit.is_hit());
  EXPECT_LE((*empty)->memory_bytes(), EmbreeBrickAccel::reserve_bytes(0, {}));

  BrickData bad;
  bad.brick_id = 17;
  bad.triangles.resize(3);
  bad.ids.resize(2);
  auto status = EmbreeBrickAccel::build(std::move(bad), {});
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.status().message().find("brick 17"), std::string::npos) << status.status().to_string();
}

TEST(EmbreeBrick, SpareCapacityIsUsedInPlace) {
  const BrickData sphere = load_brick_from("gen:sphere?level=4");
  BrickData tight = sphere, spare = sphere;
  tight.triangles.shrink_to_fit();
  spare.triangles.reserve(spare.triangles.size() + 1);
  const auto a = build_or_die(std::move(tight));
  const auto b = build_or_die(std::move(spare));
  ASSERT_TRUE(a && b);
  // Without slack the soup is copied once, which can only raise the peak.
  EXPECT_LE(b->build_peak_bytes(), a->build_peak_bytes());
  EXPECT_EQ(b->memory_bytes(), a->memory_bytes());
  const auto rays = rays_from_outside(bounds_of(sphere), 2000, 61);
  std::vector<Hit> ha(rays.size()), hb(rays.size());
  a->intersect(all_ids(rays.size()), rays.data(), ha.data());
  b->intersect(all_ids(rays.size()), rays.data(), hb.data());
  EXPECT_EQ(std::memcmp(ha.data(), hb.data(), ha.size() * sizeof(Hit)), 0);
}

// memory_bytes() and the build's peak stay within reserve_bytes() for every
// shape, size and option combination (the sweep to 1e6 triangles for every
// combination is EmbreeBrickMeasure.DISABLED_MemoryTable; here up to 3e4, and
// 1e6 with the default options); Embree's bytes go back to where they were
// once the bricks are released.
TEST(EmbreeBrick, MemoryStaysWithinReserve) {
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  const BrickData bunny = load_brick_from(bunny_path());
  const BrickData sphere = load_brick_from("gen:sphere?level=6");
  const BrickData random = random_triangles(30000, 71);
  const BrickData scattered = scattered_triangles(30000, 73);
  const BrickData degenerate = degenerate_heavy(30000, 72);
  const int64_t live_before = (*device)->live_bytes();
  const auto check = [&](const char* name, const BrickData& base, uint64_t n,
                         const EmbreeBrickConfig& config) {
    SCOPED_TRACE(std::string(name) + " n=" + std::to_string(n) + " " + describe(config));
    const auto accel = build_or_die(resized(base, n), config);
    ASSERT_NE(accel, nullptr);
    const uint64_t reserve = EmbreeBrickAccel::reserve_bytes(n, config);
    EXPECT_GT(accel->embree_bytes(), 0u);
    EXPECT_LE(accel->memory_bytes(), accel->build_peak_bytes());
    EXPECT_LE(accel->memory_bytes(), reserve);
    EXPECT_LE(accel->build_peak_bytes(), reserve);
  };
  for (const auto& [name, base] :
       {std::pair{"bunny", &bunny}, std::pair{"sphere", &sphere}, std::pair{"random", &random},
        std::pair{"scattered", &scattered}, std::pair{"degenerate", &degenerate}}) {
    for (uint64_t n : {10ull, 1000ull, 30000ull}) {
      for (const auto& config : all_configs()) check(name, *base, n, config);
    }
  }
#ifndef OUTCORE_SANITIZE_BUILD
  check("bunny", bunny, 1000000, {});
#endif
  EXPECT_EQ((*device)->live_bytes(), live_before);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
