#include "core/proxy/proxy_builder.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/accel/brute_force_reference.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

Vec3f random_point(std::mt19937_64& rng, const Aabb& box) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const Vec3f e = box.extent();
  return {box.lo.x + u(rng) * e.x, box.lo.y + u(rng) * e.y, box.lo.z + u(rng) * e.z};
}

// Triangles of every kind inside `box`: tiny, medium, spanning the box,
// slivers, axis-aligned, degenerate (a segment and a point).
std::vector<Triangle> random_triangles(std::mt19937_64& rng, const Aabb& box, std::size_t n) {
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Triangle> out;
  const float size = box.extent().x;
  for (std::size_t i = 0; i < n; ++i) {
    Triangle t;
    t.v0 = random_point(rng, box);
    const float reach = (i % 4 == 0) ? 1.0f : (i % 4 == 1 ? 0.2f : 0.02f);
    auto near = [&](const Vec3f& p) {
      Vec3f q(p.x + (u(rng) - 0.5f) * reach * size, p.y + (u(rng) - 0.5f) * reach * size,
              p.z + (u(rng) - 0.5f) * reach * size);
      return max(box.lo, min(box.hi, q));
    };
    t.v1 = near(t.v0);
    t.v2 = near(t.v0);
    if (i % 17 == 0) t.v2 = t.v1;                                              // a segment
    if (i % 23 == 0) t.v1 = t.v2 = t.v0;                                       // a point
    if (i % 13 == 0) t.v1.z = t.v2.z = t.v0.z;                                 // axis-aligned
    if (i % 19 == 0) t.v2 = t.v0 + (t.v1 - t.v0) * 0.5f + Vec3f(0, 1e-6f, 0);  // a sliver
    out.push_back(t);
  }
  return out;
}

Aabb bounds_of(const std::vector<Triangle>& tris) {
  Aabb b;
  for (const Triangle& t : tris) b.extend(t.bounds());
  return b;
}

// The index of the voxel holding a world point.
std::array<int32_t, 3> voxel_of(const ProxyFrame& f, const Vec3d& p) {
  const Vec3d q = f.world_to_index(p);
  return {static_cast<int32_t>(std::floor(q.x)), static_cast<int32_t>(std::floor(q.y)),
          static_cast<int32_t>(std::floor(q.z))};
}

// Rays tried against a proxy: those the float64 reference hits among a
// brick's triangles, and those the proxy skips. add() is false when the
// proxy would skip a ray the reference hits (what no proxy may do).
struct ProxyTally {
  int hits = 0;
  int skipped = 0;
  bool add(const BrickProxy& proxy, const std::vector<Triangle>& tris, const Ray& r, double rounding_scale) {
    bool hit = false;
    for (const Triangle& t : tris) hit = hit || reference_triangle_hit(t, r).has_value();
    const bool may = proxy.may_hit(r, r.tnear, r.tfar, rounding_scale);
    hits += hit;
    skipped += !may;
    return may || !hit;
  }
};

TEST(ProxyBuilder, TriangleBoxOverlapNeverMissesASampledContact) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Aabb space{{0, 0, 0}, {1, 1, 1}};
  int contacts = 0, separated = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const Triangle t = random_triangles(rng, space, 1)[0];
    // Boxes near the triangle's first vertex, so that about half touch it.
    const Vec3d centre = Vec3d(t.v0) + Vec3d(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5) * 0.4;
    const Vec3d half(0.02 + 0.1 * u(rng), 0.02 + 0.1 * u(rng), 0.02 + 0.1 * u(rng));
    const bool overlaps = triangle_overlaps_box(Vec3d(t.v0), Vec3d(t.v1), Vec3d(t.v2), centre, half);
    bool sampled = false;
    for (int a = 0; a <= 40 && !sampled; ++a) {
      for (int b = 0; a + b <= 40 && !sampled; ++b) {
        const Vec3d p =
            Vec3d(t.v0) + (Vec3d(t.v1) - Vec3d(t.v0)) * (a / 40.0) + (Vec3d(t.v2) - Vec3d(t.v0)) * (b / 40.0);
        sampled = std::fabs(p.x - centre.x) <= half.x && std::fabs(p.y - centre.y) <= half.y &&
                  std::fabs(p.z - centre.z) <= half.z;
      }
    }
    if (sampled) {
      ++contacts;
      EXPECT_TRUE(overlaps) << "trial " << trial;
    }
    separated += !overlaps;
  }
  EXPECT_GT(contacts, 100);
  EXPECT_GT(separated, 300);  // the test is not trivially true
}

TEST(ProxyBuilder, EveryPointOfEveryTriangleAndItsMarginIsInAnOccupiedVoxel) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const float scale : {1.0f, 1e-3f, 250.0f}) {
    const Aabb space{{-3 * scale, 1 * scale, 2 * scale}, {-1 * scale, 3 * scale, 4 * scale}};
    const auto tris = random_triangles(rng, space, 300);
    for (const uint32_t res : {1u, 7u, 32u}) {
      ProxyBuildConfig config;
      config.resolution = res;
      const Aabb box = bounds_of(tris);
      const BrickProxy proxy = build_brick_proxy(box, box, tris, config);
      const ProxyFrame& f = proxy.frame();
      ASSERT_GT(f.voxel_size_WS, 0);
      const double longest =
          std::max({double(box.hi.x) - box.lo.x, double(box.hi.y) - box.lo.y, double(box.hi.z) - box.lo.z});
      EXPECT_DOUBLE_EQ(f.voxel_size_WS, longest / res);
      EXPECT_GE(f.margin_WS, 0.25 * f.voxel_size_WS);
      uint64_t samples = 0;
      for (std::size_t k = 0; k < tris.size(); ++k) {
        const Vec3d v0(tris[k].v0), v1(tris[k].v1), v2(tris[k].v2);
        for (int a = 0; a <= 12; ++a) {
          for (int b = 0; a + b <= 12; ++b) {
            const Vec3d p = v0 + (v1 - v0) * (a / 12.0) + (v2 - v0) * (b / 12.0);
            // The point itself and a point within 0.9 margins of it (max norm).
            const Vec3d q = p + Vec3d(u(rng), u(rng), u(rng)) * (0.9 * f.margin_WS);
            for (const Vec3d& s : {p, q}) {
              const auto c = voxel_of(f, s);
              ++samples;
              ASSERT_TRUE(proxy.is_occupied(c[0], c[1], c[2]))
                  << "triangle " << k << " res " << res << " scale " << scale;
            }
          }
        }
      }
      EXPECT_GT(samples, 10000u);
    }
  }
}

TEST(ProxyBuilder, FrameSpansTheBoxPlusAVoxelAndHandlesFlatAndPointBricks) {
  ProxyBuildConfig config;
  config.resolution = 32;
  const Aabb cube_box{{0, 0, 0}, {2, 1, 0.5f}};
  const ProxyFrame cube = proxy_frame_for(cube_box, cube_box, config);
  EXPECT_DOUBLE_EQ(cube.voxel_size_WS, 2.0 / 32);
  EXPECT_EQ(cube.dims_IS[0], 34);
  EXPECT_EQ(cube.dims_IS[1], 18);
  EXPECT_EQ(cube.dims_IS[2], 10);
  EXPECT_DOUBLE_EQ(cube.origin_WS.x, -2.0 / 32);

  // A flat brick (a ground plane) and a brick of one point.
  const std::vector<Triangle> flat = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  const BrickProxy plane = build_brick_proxy(bounds_of(flat), bounds_of(flat), flat, config);
  EXPECT_EQ(plane.frame().dims_IS[2], 2);
  Ray above;
  above.origin = {-0.5f, 0.2f, 0.2f};
  above.direction = {1, 0, 0};
  EXPECT_FALSE(plane.may_hit(above, 0, 10, kMollerTrumboreHitRounding));  // beyond the grid's domain
  Ray down;
  down.origin = {0.2f, 0.2f, 1};
  down.direction = {0, 0, -1};
  EXPECT_TRUE(plane.may_hit(down, 0, 10, kMollerTrumboreHitRounding));
  down.origin = {0.9f, 0.9f, 1};  // over the box, beside the triangle
  EXPECT_FALSE(plane.may_hit(down, 0, 10, kMollerTrumboreHitRounding));

  const std::vector<Triangle> point = {{{5, 5, 5}, {5, 5, 5}, {5, 5, 5}}};
  const BrickProxy dot = build_brick_proxy(bounds_of(point), bounds_of(point), point, config);
  EXPECT_GT(dot.frame().voxel_size_WS, 0);
  Ray through;
  through.origin = {0, 0, 0};
  through.direction = {1, 1, 1};
  // Its voxels are far below float rounding at its coordinates: never skipped.
  EXPECT_TRUE(dot.may_hit(through, 0, 10, kMollerTrumboreHitRounding));
  EXPECT_TRUE(dot.may_hit(through, 0, 4.9f, kMollerTrumboreHitRounding));
}

TEST(ProxyBuilder, RaysThroughTheEmptyPartOfABrickAreSkipped) {
  // Two small clusters in opposite corners of the unit cube.
  std::vector<Triangle> tris;
  for (const float c : {0.0f, 0.9f}) {
    tris.push_back({{c, c, c}, {c + 0.1f, c, c}, {c, c + 0.1f, c + 0.1f}});
    tris.push_back({{c + 0.1f, c + 0.1f, c + 0.1f}, {c + 0.1f, c, c}, {c, c + 0.1f, c + 0.1f}});
  }
  const BrickProxy proxy = build_brick_proxy(bounds_of(tris), bounds_of(tris), tris, ProxyBuildConfig{});
  auto ray = [](Vec3f o, Vec3f d) {
    Ray r;
    r.origin = o;
    r.direction = d;
    return r;
  };
  const float inf = std::numeric_limits<float>::infinity();
  // Across the middle, along the other diagonal, and along the axes.
  EXPECT_FALSE(proxy.may_hit(ray({-1, 2, 0.5f}, {1, -1, 0}), 0, inf, kMollerTrumboreHitRounding));
  EXPECT_FALSE(proxy.may_hit(ray({0.5f, 0.5f, -1}, {0, 0, 1}), 0, inf, kMollerTrumboreHitRounding));
  EXPECT_FALSE(proxy.may_hit(ray({-1, 0.5f, 0.5f}, {1, 0, 0}), 0, inf, kMollerTrumboreHitRounding));
  EXPECT_FALSE(proxy.may_hit(ray({0.05f, 0.95f, -3}, {0, 0, 1}), 0, inf, kMollerTrumboreHitRounding));
  // Through a cluster; then the same ray ending before it or starting after it.
  EXPECT_TRUE(proxy.may_hit(ray({-1, -1, -1}, {1, 1, 1}), 0, inf, kMollerTrumboreHitRounding));
  EXPECT_TRUE(proxy.may_hit(ray({0.05f, 0.05f, -3}, {0, 0, 1}), 0, inf, kMollerTrumboreHitRounding));
  EXPECT_FALSE(proxy.may_hit(ray({0.05f, 0.05f, -3}, {0, 0, 1}), 0, 2.5f, kMollerTrumboreHitRounding));
  EXPECT_FALSE(proxy.may_hit(ray({0.05f, 0.05f, -3}, {0, 0, 1}), 3.5f, inf, kMollerTrumboreHitRounding));
  EXPECT_TRUE(proxy.may_hit(ray({0.05f, 0.05f, -3}, {0, 0, 2}), 0, 1.6f,
                            kMollerTrumboreHitRounding));  // t in direction lengths
  // Misses the domain altogether.
  EXPECT_FALSE(proxy.may_hit(ray({5, 5, 5}, {1, 0, 0}), 0, inf, kMollerTrumboreHitRounding));
}

TEST(ProxyBuilder, MayHitIsTrueForEveryRayTheFloat64ReferenceHits) {
  std::mt19937_64 rng(3);
  const Aabb space{{10, -2, 3}, {12, 0, 5}};
  const auto tris = random_triangles(rng, space, 60);
  const Aabb box = bounds_of(tris);
  const BrickProxy proxy = build_brick_proxy(box, box, tris, ProxyBuildConfig{});
  const Aabb around{box.lo - box.extent(), box.hi + box.extent()};
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  ProxyTally tally;
  for (int i = 0; i < 20000; ++i) {
    Ray r;
    r.origin = random_point(rng, i % 2 ? around : box);
    r.direction = random_point(rng, box) - r.origin;
    if (i % 5 == 0) r.direction = {0, 0, r.direction.z};  // axis-parallel
    if (r.direction == Vec3f(0, 0, 0)) continue;
    if (i % 3 == 0) r.tfar = u(rng);
    if (i % 7 == 0) r.tnear = 0.5f * u(rng);
    ASSERT_TRUE(tally.add(proxy, tris, r, kMollerTrumboreHitRounding))
        << "ray " << i << " hits but is skipped";
  }
  EXPECT_GT(tally.hits, 1000);
  EXPECT_GT(tally.skipped, 2000);
}

TEST(ProxyBuilder, TooSmallABrickForItsDistanceFromTheOriginIsNeverSkipped) {
  // A brick of 1 unit at 1e7: float rounding there exceeds a voxel.
  const std::vector<Triangle> tris = {{{1e7f, 1e7f, 1e7f}, {1e7f + 1, 1e7f, 1e7f}, {1e7f, 1e7f + 1, 1e7f}}};
  const BrickProxy proxy = build_brick_proxy(bounds_of(tris), bounds_of(tris), tris, ProxyBuildConfig{});
  Ray r;
  r.origin = {1e7f + 0.9f, 1e7f + 0.9f, 1e7f - 5};
  r.direction = {0, 0, 1};
  EXPECT_TRUE(proxy.may_hit(r, 0, std::numeric_limits<float>::infinity(), kMollerTrumboreHitRounding));
  // Near the origin the same shape is skipped beside the triangle.
  const std::vector<Triangle> near = {{{1, 1, 1}, {2, 1, 1}, {1, 2, 1}}};
  const BrickProxy small = build_brick_proxy(bounds_of(near), bounds_of(near), near, ProxyBuildConfig{});
  r.origin = {1.9f, 1.9f, -4};
  EXPECT_FALSE(small.may_hit(r, 0, std::numeric_limits<float>::infinity(), kMollerTrumboreHitRounding));
  // ... unless the ray comes from very far away.
  r.origin = {1.9f, 1.9f, -1e6f};
  EXPECT_TRUE(small.may_hit(r, 0, std::numeric_limits<float>::infinity(), kMollerTrumboreHitRounding));
}

TEST(ProxyBuilder, ResolutionIsRangeChecked) {
  ProxyBuildConfig config;
  EXPECT_TRUE(validate_proxy_config(config).ok());
  config.resolution = 0;
  EXPECT_EQ(validate_proxy_config(config).code(), StatusCode::kInvalidArgument);
  config.resolution = kMaxProxyResolution + 1;
  const Status s = validate_proxy_config(config);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("proxy resolution"), std::string::npos) << s.message();
}

TEST(ProxyBuilder, MarginsGrowWithTheScenesReachSoFarBricksStillSkip) {
  // A 3-unit brick 3900 units from the origin in an 8000-unit flat scene: a
  // quarter voxel (0.023) is below twice the watertight rounding bound of a
  // ray from 8000 units away, so without the grown margin every such ray
  // would be answered "may hit".
  const Aabb scene{{-4000, -2, -4000}, {4000, 2, 4000}};
  std::vector<Triangle> tris;
  for (const float c : {0.0f, 2.7f}) {  // clusters in opposite corners
    const Vec3f o(3900 + c, -1.5f + c, 3900 + c);
    tris.push_back({o, o + Vec3f(0.3f, 0, 0), o + Vec3f(0, 0.3f, 0.3f)});
  }
  const Aabb box = bounds_of(tris);
  const BrickProxy proxy = build_brick_proxy(box, scene, tris, ProxyBuildConfig{});
  const ProxyFrame& f = proxy.frame();
  // A quarter voxel would not do for a ray from 4000 units away ...
  EXPECT_GT(2 * proxy_rounding_bound(kWatertightHitRounding, 4000, f.domain_magnitude_WS()),
            0.25 * f.voxel_size_WS);
  EXPECT_GT(f.margin_WS, 0.25 * f.voxel_size_WS);
  EXPECT_LE(f.margin_WS, kMaxProxyMarginVoxels * f.voxel_size_WS);
  const double reach = proxy_origin_reach(scene);
  EXPECT_DOUBLE_EQ(reach, 12000);
  EXPECT_GE(f.margin_WS, 2 * proxy_rounding_bound(kWatertightHitRounding, reach, f.domain_magnitude_WS()));

  // ... so from 8000 units away, across the empty middle of the brick, only
  // the grown margin lets the proxy skip.
  Ray across;
  across.origin = {-4000, 0, -4000};
  across.direction = Vec3f(3901.5f, 0, 3901.5f) - across.origin;
  EXPECT_FALSE(proxy.may_hit(across, 0, std::numeric_limits<float>::infinity(), kWatertightHitRounding));

  // Never skipped when the reference hits, from anywhere in the reach.
  std::mt19937_64 rng(11);
  const Aabb around{{-12000, -4000, -12000}, {12000, 4000, 12000}};
  ProxyTally tally;
  for (int i = 0; i < 20000; ++i) {
    Ray r;
    r.origin = random_point(rng, around);
    const Triangle& aim = tris[i % tris.size()];
    const Vec3f target =
        i % 2 ? random_point(rng, box) : aim.v0 + (aim.v1 - aim.v0) * 0.3f + (aim.v2 - aim.v0) * 0.3f;
    r.direction = target - r.origin;
    ASSERT_TRUE(tally.add(proxy, tris, r, kWatertightHitRounding)) << "ray " << i << " hits but is skipped";
  }
  EXPECT_GT(tally.hits, 5000);
  EXPECT_GT(tally.skipped, 5000);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
