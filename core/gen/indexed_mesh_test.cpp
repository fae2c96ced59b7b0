#include "core/gen/indexed_mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(GenIndexedMesh, RoundTripsTrianglesInOrder) {
  // Vertices drawn from a small pool, so many are shared; enough to force rehashes.
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> pick(0, 2999);
  std::vector<Vec3f> pool;
  for (int i = 0; i < 3000; ++i)
    pool.emplace_back(static_cast<float>(i) * 0.25f, -static_cast<float>(i % 17), 1.5f);
  std::vector<Triangle> input;
  IndexedMeshBuilder builder;
  for (int k = 0; k < 20000; ++k) {
    input.push_back({pool[pick(rng)], pool[pick(rng)], pool[pick(rng)]});
    ASSERT_TRUE(builder.add(input.back()).ok());
  }
  const IndexedMesh mesh = builder.finish();
  ASSERT_EQ(mesh.triangle_count(), input.size());
  for (std::size_t k = 0; k < input.size(); ++k) ASSERT_EQ(mesh.triangle(k), input[k]) << k;
  EXPECT_LE(mesh.vertices.size(), 3000u);
  EXPECT_GT(mesh.vertices.size(), 2900u);
  const Aabb b = mesh.bounds();
  EXPECT_EQ(b.lo, Vec3f(0, -16, 1.5f));
}

TEST(GenIndexedMesh, WeldsByExactBits) {
  IndexedMeshBuilder builder;
  const Vec3f a(0.0f, 1, 2), neg_zero(-0.0f, 1, 2), near(std::nextafter(0.0f, 1.0f), 1, 2);
  ASSERT_TRUE(builder.add({a, neg_zero, near}).ok());
  ASSERT_TRUE(builder.add({near, a, a}).ok());
  const IndexedMesh mesh = builder.finish();
  EXPECT_EQ(mesh.vertices.size(), 3u);  // -0 and +0 differ in bits, so stay apart
  EXPECT_EQ(std::signbit(mesh.triangle(0).v1.x), true);
  EXPECT_EQ(mesh.triangles[1], (std::array<uint32_t, 3>{2, 0, 0}));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
