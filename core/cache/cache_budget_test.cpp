#include "core/cache/cache_budget.h"

#include <gtest/gtest.h>

namespace outcore {
namespace OUTCORE_UNITY_ID {

Manifest manifest_with_bricks(std::initializer_list<uint32_t> triangle_counts) {
  Manifest manifest;
  for (uint32_t count : triangle_counts) {
    BrickRecord brick;
    brick.triangle_count = count;
    manifest.bricks.push_back(brick);
  }
  return manifest;
}

TEST(CacheBudget, TheMinimumIsTheLargestBricksReservation) {
  for (const char* accel : {"embree", "bvh", "reference"}) {
    SCOPED_TRACE(accel);
    auto builder = make_brick_builder(accel, {});
    ASSERT_TRUE(builder.ok()) << builder.status().message();
    const Manifest manifest = manifest_with_bricks({100, 70000, 5, 70000, 300});
    const MinimumCacheBudget minimum = minimum_cache_budget(manifest, **builder);
    EXPECT_EQ(minimum.bytes, (*builder)->reserve_bytes(70000));
    EXPECT_EQ(minimum.brick_id, 1u);  // the first of the largest
    EXPECT_EQ(minimum.triangle_count, 70000u);
    EXPECT_GE(minimum.mib() << 20, minimum.bytes);
    EXPECT_LT((minimum.mib() - 1) << 20, minimum.bytes);
    // Exactly the reservation is enough; a byte less names brick 1 and the MiB figure.
    EXPECT_TRUE(check_cache_budget(manifest, **builder, minimum.bytes).ok());
    const Status refused = check_cache_budget(manifest, **builder, minimum.bytes - 1);
    EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(refused.message().find("brick 1 (70000 triangles)"), std::string::npos) << refused.message();
    EXPECT_NE(refused.message().find("--cache-mb " + std::to_string(minimum.mib())), std::string::npos)
        << refused.message();
  }
}

TEST(CacheBudget, ASceneWithoutBricksNeedsNothing) {
  auto builder = make_brick_builder("bvh", {});
  ASSERT_TRUE(builder.ok());
  const MinimumCacheBudget minimum = minimum_cache_budget(Manifest{}, **builder);
  EXPECT_EQ(minimum.bytes, 0u);
  EXPECT_EQ(minimum.mib(), 0u);
  EXPECT_TRUE(check_cache_budget(Manifest{}, **builder, 1).ok());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
