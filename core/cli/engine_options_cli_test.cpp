#include "core/cli/engine_options_cli.h"

#include <gtest/gtest.h>

#include <string>

namespace outcore {
namespace OUTCORE_UNITY_ID {

Status apply(const EngineCliOptions& cli, EngineOptions* out = nullptr) {
  EngineOptions options;
  const Status status = apply_engine_options(cli, options);
  if (out != nullptr) *out = std::move(options);
  return status;
}

TEST(EngineOptionsCli, GoodOptionsReachTheEngineOptions) {
  EngineCliOptions cli;
  cli.cache_mb = 3;
  cli.policy = "lfu";
  cli.brick_accel = "bvh";
  cli.proxy_res = 16;
  cli.accel_options = {"leaf_size=4"};
  cli.triangle_test = "mt";
  EngineOptions options;
  ASSERT_TRUE(apply(cli, &options).ok());
  EXPECT_EQ(options.cache_bytes, uint64_t{3} << 20);
  EXPECT_EQ(options.eviction_policy, "lfu");
  EXPECT_EQ(options.brick_accel, "bvh");
  EXPECT_TRUE(options.proxies);
  EXPECT_EQ(options.proxy_config.resolution, 16u);
  EXPECT_EQ(options.accel_options.at("leaf_size"), "4");
  EXPECT_EQ(options.accel_options.at("triangle_test"), "mt");

  EngineCliOptions reference;
  reference.reference = true;
  reference.no_proxies = true;
  ASSERT_TRUE(apply(reference, &options).ok());
  EXPECT_EQ(options.brick_accel, "reference");
  EXPECT_FALSE(options.proxies);
}

// Each bad option is an error naming it (and the value where there is one),
// as `trace` and `serve` both print it.
TEST(EngineOptionsCli, ABadOptionIsNamedInTheError) {
  struct Case {
    EngineCliOptions cli;
    std::string message;
  };
  std::vector<Case> cases(9);
  cases[0].cli.cache_mb = 0;
  cases[0].message = "--cache-mb must be between 1 and 17592186044415, got 0";
  cases[1].cli.proxy_res = 1'000'000;
  cases[1].message = "--proxy-res must be between";
  cases[2].cli.no_proxies = true;
  cases[2].cli.proxy_res = 16;
  cases[2].message = "--proxy-res has no effect with --no-proxies; give one of them";
  cases[3].cli.accel_options = {"novalue"};
  cases[3].message = "--accel-opt 'novalue' is not of the form key=value";
  cases[4].cli.accel_options = {"a=1", "a=2"};
  cases[4].message = "--accel-opt 'a' given twice";
  cases[5].cli.brick_accel = "embree";
  cases[5].cli.triangle_test = "mt";
  cases[5].message =
      "--triangle-test needs --brick-accel bvh|kdtree|bsp|grid|hgrid|octree|quadtree|auto (got 'embree')";
  cases[6].cli.reference = true;
  cases[6].cli.brick_accel = "embree";
  cases[6].message = "--reference chooses the brick structure itself";
  cases[7].cli.brick_accel = "embree";
  cases[7].cli.subtree.dir = "/tmp/x";
  cases[7].message =
      "--subtree-dir needs --brick-accel bvh|kdtree|bsp|grid|hgrid|octree|quadtree|auto (got 'embree'";
  cases[8].cli.brick_bounds = "kdop";
  cases[8].message = "--brick-bounds must be aabb, sphere or obb, got 'kdop'";
  for (const Case& c : cases) {
    const Status status = apply(c.cli);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << c.message;
    EXPECT_NE(status.message().find(c.message), std::string::npos) << status.message();
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
