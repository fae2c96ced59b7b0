// WatertightRefLanes against WatertightTriangleTest::hit one reference at a
// time: the same hits with bitwise the same t, u, v, for runs of 1 to 11
// references (whole and partial groups of four), random rays and rays aimed
// at shared vertices and edges of a fan, at offsets up to 1e6; the mailbox
// still tests a repeated reference once; a true from on_hit stops the test.
#include "core/accel/kdtree/watertight_ref_lanes.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "core/accel/triangle_mailbox.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

struct RefHit {
  uint32_t triangle;
  TriangleHit hit;
  bool operator==(const RefHit& o) const {
    return triangle == o.triangle && std::memcmp(&hit, &o.hit, sizeof(hit)) == 0;
  }
};

std::vector<RefHit> scalar_hits(const Ray& ray, const std::vector<Triangle>& triangles,
                                const std::vector<uint32_t>& refs) {
  const WatertightTriangleTest::Prepared prepared = WatertightTriangleTest::prepare(ray);
  std::vector<RefHit> hits;
  for (const uint32_t tri : refs) {
    TriangleHit h;
    if (WatertightTriangleTest::hit(prepared, triangles[tri], ray.tnear, ray.tfar, h))
      hits.push_back({tri, h});
  }
  return hits;
}

std::vector<RefHit> lane_hits(const Ray& ray, const std::vector<Triangle>& triangles,
                              const std::vector<uint32_t>& refs) {
  kd_detail::WatertightRefLanes lanes(WatertightTriangleTest::prepare(ray));
  NoMailbox mailbox;
  std::vector<RefHit> hits;
  const float tfar = ray.tfar;
  const bool stopped = lanes.test(refs.data(), static_cast<uint32_t>(refs.size()), triangles.data(), mailbox,
                                  ray.tnear, tfar, [&](uint32_t tri, const TriangleHit& h) {
                                    hits.push_back({tri, h});
                                    return false;
                                  });
  EXPECT_FALSE(stopped);
  return hits;
}

// A fan of `n` triangles around `center`: rays through the centre and along
// the spokes hit shared vertices and edges.
std::vector<Triangle> fan(const Vec3f& center, uint32_t n, float radius) {
  std::vector<Triangle> triangles;
  for (uint32_t k = 0; k < n; ++k) {
    const double a0 = 2 * M_PI * k / n, a1 = 2 * M_PI * (k + 1) / n;
    const Vec3f p0 = center + Vec3f(radius * std::cos(a0), radius * std::sin(a0), 0.1f * radius * (k % 3));
    const Vec3f p1 =
        center + Vec3f(radius * std::cos(a1), radius * std::sin(a1), 0.1f * radius * ((k + 1) % 3));
    triangles.push_back({center, p0, p1});
  }
  return triangles;
}

TEST(WatertightRefLanes, HitsAreBitwiseTheScalarTestsOnWholeAndPartialGroups) {
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  uint64_t hits = 0;
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const Vec3f center(offset, -offset, 0.5f * offset);
    const std::vector<Triangle> triangles = fan(center, 11, 1.0f);
    for (uint32_t count = 1; count <= triangles.size(); ++count) {
      std::vector<uint32_t> refs;
      for (uint32_t k = 0; k < count; ++k) refs.push_back((k * 7) % 11);
      for (int r = 0; r < 300; ++r) {
        Ray ray;
        ray.origin = center + Vec3f(0.3f * unit(rng), 0.3f * unit(rng), 3.0f);
        // Aimed at the shared centre, a spoke's point or a random one.
        Vec3f target = center;
        if (r % 3 == 1) target = triangles[r % 11].v1;
        if (r % 3 == 2) target = center + Vec3f(unit(rng), unit(rng), 0.0f);
        ray.direction = target - ray.origin;
        ray.tnear = 0.0f;
        ray.tfar = r % 5 == 0 ? 0.5f : INFINITY;  // some segments end short of the fan
        const std::vector<RefHit> expected = scalar_hits(ray, triangles, refs);
        hits += expected.size();
        ASSERT_EQ(lane_hits(ray, triangles, refs), expected) << "offset " << offset << " refs " << count;
      }
    }
  }
  EXPECT_GT(hits, 1000u);
}

TEST(WatertightRefLanes, TheMailboxTestsARepeatedReferenceOnceAndOnHitCanStop) {
  const std::vector<Triangle> triangles = fan({0, 0, 0}, 6, 1.0f);
  Ray ray;
  ray.origin = {0.0f, 0.0f, 2.0f};
  ray.direction = {0.01f, 0.02f, -1.0f};
  ray.tnear = 0.0f;
  ray.tfar = INFINITY;
  const std::vector<uint32_t> refs = {0, 1, 2, 3, 4, 5, 0, 1, 2, 3, 4, 5, 5};
  kd_detail::WatertightRefLanes lanes(WatertightTriangleTest::prepare(ray));
  TriangleMailbox mailbox;
  uint32_t calls = 0;
  const float tfar = ray.tfar;
  EXPECT_FALSE(lanes.test(refs.data(), static_cast<uint32_t>(refs.size()), triangles.data(), mailbox, 0.0f,
                          tfar, [&](uint32_t, const TriangleHit&) {
                            ++calls;
                            return false;
                          }));
  EXPECT_EQ(calls, 1u);  // one triangle of the fan holds the point, tested once
  NoMailbox none;
  calls = 0;
  EXPECT_TRUE(lanes.test(refs.data(), static_cast<uint32_t>(refs.size()), triangles.data(), none, 0.0f, tfar,
                         [&](uint32_t, const TriangleHit&) {
                           ++calls;
                           return true;
                         }));
  EXPECT_EQ(calls, 1u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
