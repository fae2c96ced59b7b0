#include "core/cache/lfu_policy.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::any_brick;
using testing_policy::drain;
using testing_policy::evict_one;

TEST(LfuPolicyTest, EvictsTheLeastFrequentlyUsedLeastRecentFirst) {
  LfuPolicy lfu;
  EXPECT_EQ(lfu.name(), "lfu");
  for (uint32_t b : {0u, 1u, 2u, 3u}) lfu.on_insert(b, 1, 0.0);
  lfu.on_access(0);
  lfu.on_access(0);
  lfu.on_access(2);
  // keys: 0 -> 3, 1 -> 1, 2 -> 2, 3 -> 1 (1 older than 3)
  EXPECT_EQ(lfu.order(), (std::vector<uint32_t>{1, 3, 2, 0}));
  EXPECT_EQ(drain(lfu), (std::vector<uint32_t>{1, 3, 2, 0}));
}

TEST(LfuPolicyTest, AgingLetsNewcomersCatchUpWithFormerlyHotBricks) {
  LfuPolicy lfu;
  lfu.on_insert(0, 1, 0.0);
  for (int i = 0; i < 4; ++i) lfu.on_access(0);  // key 5: hot in an early phase
  lfu.on_insert(1, 1, 0.0);
  EXPECT_EQ(lfu.age(), 0u);
  // A new phase: newcomers hit twice each, one at a time. Without aging they
  // (key 2) would always go before 0 (key 5); with it L climbs to 1, then 3,
  // and the third newcomer's key passes 0's stale one.
  uint32_t next = 2;
  int rounds = 0;
  for (;;) {
    const auto victim = evict_one(lfu);
    ASSERT_TRUE(victim.has_value());
    if (*victim == 0) break;
    EXPECT_EQ(*victim, next - 1);
    lfu.on_insert(next, 1, 0.0);
    lfu.on_access(next);
    ++next;
    ASSERT_LT(++rounds, 10) << "the formerly hot brick never aged out";
  }
  EXPECT_EQ(rounds, 2);
  EXPECT_EQ(lfu.age(), 5u);
}

TEST(LfuPolicyTest, AgeIsTheLastVictimsKey) {
  LfuPolicy lfu;
  lfu.on_insert(5, 1, 0.0);
  lfu.on_access(5);
  lfu.on_access(5);  // key 3
  lfu.on_insert(6, 1, 0.0);
  lfu.on_access(6);
  lfu.on_access(6);
  lfu.on_access(6);  // key 4
  EXPECT_EQ(evict_one(lfu), 5u);
  EXPECT_EQ(lfu.age(), 3u);
  lfu.on_insert(7, 1, 0.0);
  EXPECT_EQ(lfu.key(7), 4u);  // L + 1, level with 6: 6 is older
  EXPECT_EQ(evict_one(lfu), 6u);
}

TEST(LfuPolicyTest, SkipsPinnedBricks) {
  LfuPolicy lfu;
  for (uint32_t b : {0u, 1u, 2u}) lfu.on_insert(b, 1, 0.0);
  const auto not_zero = [](uint32_t b) { return b != 0; };
  EXPECT_EQ(lfu.choose_victim(not_zero), 1u);
  EXPECT_FALSE(lfu.choose_victim([](uint32_t) { return false; }).has_value());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
