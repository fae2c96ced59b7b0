// hit_records_for: each record's normal bitwise Triangle::unit_normal (the
// paired float64 path and the odd last triangle alike), at offsets up to
// 1e6 and for slivers (collapsed ones' NaN normals included), and each record's ids those given.
#include "core/accel/triangle_hit_records.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(HitRecords, NormalsAreBitwiseTheTrianglesUnitNormalsAndIdsAreKept) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    for (const std::size_t n : {std::size_t{1}, std::size_t{2}, std::size_t{7}, std::size_t{1000}}) {
      std::vector<Triangle> triangles;
      std::vector<TriangleId> ids;
      for (std::size_t k = 0; k < n; ++k) {
        const Vec3f a(offset + unit(rng), offset + unit(rng), offset + unit(rng));
        // Every third a sliver: its normal rests on a tiny cross product.
        const float spread = k % 3 == 0 ? 1e-4f : 1.0f;
        const Vec3f b = a + Vec3f(unit(rng), unit(rng), unit(rng));
        const Vec3f c = a + Vec3f(unit(rng), unit(rng), unit(rng)) * spread;
        triangles.push_back({a, b, c});
        ids.push_back({static_cast<uint32_t>(k % 5), static_cast<uint32_t>(3 * k + 1)});
      }
      const std::vector<BvhHitRecord> records = hit_records_for(triangles, ids);
      ASSERT_EQ(records.size(), n);
      for (std::size_t k = 0; k < n; ++k) {
        const Vec3f expected = triangles[k].unit_normal();
        // Bit patterns: a collapsed sliver's normal is NaN in both.
        EXPECT_EQ(std::memcmp(&records[k].normal, &expected, sizeof(expected)), 0)
            << "triangle " << k << " of " << n << " at " << offset;
        EXPECT_EQ(records[k].geometry_id, ids[k].geometry_id);
        EXPECT_EQ(records[k].primitive_id, ids[k].primitive_id);
      }
    }
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
