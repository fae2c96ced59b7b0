#include "core/cache/gdsf_policy.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::any_brick;
using testing_policy::drain;
using testing_policy::evict_one;

TEST(GdsfPolicyTest, PriorityIsFrequencyTimesCostOverSize) {
  GdsfPolicy gdsf;
  EXPECT_EQ(gdsf.name(), "gdsf");
  gdsf.on_insert(0, 1000, 0.010);  // 1e-5 s per byte
  gdsf.on_insert(1, 4000, 0.010);  // 2.5e-6: large, same cost -> first to go
  gdsf.on_insert(2, 1000, 0.002);  // 2e-6: cheap to rebuild -> goes first
  EXPECT_DOUBLE_EQ(gdsf.priority(0), 1e-5);
  EXPECT_EQ(gdsf.order(), (std::vector<uint32_t>{2, 1, 0}));
  gdsf.on_access(2);
  gdsf.on_access(2);  // 6e-6: now above 1
  EXPECT_DOUBLE_EQ(gdsf.priority(2), 6e-6);
  EXPECT_EQ(drain(gdsf), (std::vector<uint32_t>{1, 2, 0}));
}

TEST(GdsfPolicyTest, InflationIsTheLastVictimsPriority) {
  GdsfPolicy gdsf;
  gdsf.on_insert(0, 100, 0.001);  // 1e-5
  gdsf.on_insert(1, 100, 0.002);  // 2e-5
  EXPECT_EQ(evict_one(gdsf), 0u);
  EXPECT_DOUBLE_EQ(gdsf.inflation(), 1e-5);
  gdsf.on_insert(2, 100, 0.0015);  // L + 1.5e-5 = 2.5e-5 > 1's 2e-5
  EXPECT_DOUBLE_EQ(gdsf.priority(2), 2.5e-5);
  EXPECT_EQ(evict_one(gdsf), 1u);
  EXPECT_DOUBLE_EQ(gdsf.inflation(), 2e-5);
  gdsf.on_access(2);  // 2e-5 + 2 * 1.5e-5
  EXPECT_DOUBLE_EQ(gdsf.priority(2), 5e-5);
}

TEST(GdsfPolicyTest, ZeroCostStillRanksBySizeAndFrequency) {
  GdsfPolicy gdsf;
  gdsf.on_insert(0, 10, 0.0);
  gdsf.on_insert(1, 20, 0.0);
  gdsf.on_insert(2, 10, 0.0);
  gdsf.on_access(0);
  EXPECT_EQ(drain(gdsf), (std::vector<uint32_t>{1, 2, 0}));
}

TEST(GdsfPolicyTest, SkipsPinnedBricks) {
  GdsfPolicy gdsf;
  gdsf.on_insert(0, 10, 0.001);
  gdsf.on_insert(1, 10, 0.002);
  EXPECT_EQ(gdsf.choose_victim([](uint32_t b) { return b != 0; }), 1u);
  EXPECT_EQ(gdsf.choose_victim(any_brick), 0u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
