#include "core/cache/clock_policy.h"

#include <gtest/gtest.h>

#include <set>
#include <vector>

#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::any_brick;
using testing_policy::drain;

TEST(ClockPolicyTest, WithoutHitsItIsFifo) {
  ClockPolicy clock;
  EXPECT_EQ(clock.name(), "clock");
  EXPECT_FALSE(clock.choose_victim(any_brick).has_value());
  for (uint32_t b : {4u, 2u, 7u}) clock.on_insert(b, 10, 0.0);
  EXPECT_EQ(drain(clock), (std::vector<uint32_t>{4, 2, 7}));
}

TEST(ClockPolicyTest, AHitBuysOneMoreRound) {
  ClockPolicy clock;
  for (uint32_t b : {0u, 1u, 2u, 3u}) clock.on_insert(b, 1, 0.0);
  clock.on_access(0);
  clock.on_access(2);
  // The hand passes 0 (clearing its bit), takes 1.
  ASSERT_EQ(clock.choose_victim(any_brick), 1u);
  EXPECT_FALSE(clock.referenced(0));
  EXPECT_TRUE(clock.referenced(2));
  clock.on_erase(1);
  // Circle now: 2(ref) 3 0 -> 2 passed over, 3 taken.
  ASSERT_EQ(clock.choose_victim(any_brick), 3u);
  clock.on_erase(3);
  clock.on_insert(9, 1, 0.0);  // enters behind the hand: 0 2 9
  EXPECT_EQ(clock.order(), (std::vector<uint32_t>{0, 2, 9}));
  EXPECT_EQ(drain(clock), (std::vector<uint32_t>{0, 2, 9}));
}

TEST(ClockPolicyTest, AllReferencedDegeneratesToFifoAfterOneSweep) {
  ClockPolicy clock;
  for (uint32_t b : {0u, 1u, 2u}) clock.on_insert(b, 1, 0.0);
  for (uint32_t b : {0u, 1u, 2u}) clock.on_access(b);
  EXPECT_EQ(clock.choose_victim(any_brick), 0u);
  for (uint32_t b : {0u, 1u, 2u}) EXPECT_FALSE(clock.referenced(b));
}

TEST(ClockPolicyTest, PinnedBricksArePassedOverUntouched) {
  ClockPolicy clock;
  for (uint32_t b : {0u, 1u, 2u}) clock.on_insert(b, 1, 0.0);
  clock.on_access(0);
  std::set<uint32_t> pinned = {0, 1};
  const auto unpinned = [&](uint32_t b) { return pinned.count(b) == 0; };
  EXPECT_EQ(clock.choose_victim(unpinned), 2u);
  EXPECT_TRUE(clock.referenced(0)) << "a pinned brick's bit must survive the sweep";
  pinned = {0, 1, 2};
  EXPECT_FALSE(clock.choose_victim(unpinned).has_value());
  pinned = {1, 2};
  EXPECT_EQ(clock.choose_victim(unpinned), 0u);  // after one pass clearing its bit
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
