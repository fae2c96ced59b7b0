#include "core/cache/schedule_policy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <span>
#include <vector>

#include "core/cache/lru_policy.h"
#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::drain;
using testing_policy::evict_one;

TEST(SchedulePolicyTest, WithoutAHintItIsLru) {
  SchedulePolicy schedule;
  LruPolicy lru;
  for (EvictionPolicy* p : {static_cast<EvictionPolicy*>(&schedule), static_cast<EvictionPolicy*>(&lru)}) {
    for (uint32_t b : {4u, 2u, 7u, 1u}) p->on_insert(b, 10, 0.1);
    p->on_access(4);
    p->on_access(7);
  }
  EXPECT_EQ(drain(schedule), drain(lru));
  EXPECT_EQ(schedule.name(), "schedule");
}

TEST(SchedulePolicyTest, EvictsBricksNoQueuedRayNeedsFirstLeastRecentlyUsedFirst) {
  SchedulePolicy p;
  for (uint32_t b : {0u, 1u, 2u, 3u, 4u}) p.on_insert(b, 10, 0.1);  // LRU order 0 1 2 3 4
  const std::vector<uint32_t> upcoming = {0, 3};
  p.on_schedule_hint(upcoming);
  // 1, 2, 4 are needed by nobody: evicted in recency order; then 3 (needed
  // later than 0), then 0.
  EXPECT_EQ(drain(p), (std::vector<uint32_t>{1, 2, 4, 3, 0}));
}

TEST(SchedulePolicyTest, AmongHintedBricksTheOneNeededLatestGoesFirst) {
  SchedulePolicy p;
  for (uint32_t b : {5u, 6u, 7u}) p.on_insert(b, 10, 0.1);
  const std::vector<uint32_t> upcoming = {7, 5, 6, 5};  // 5 listed twice: its soonest position counts
  p.on_schedule_hint(upcoming);
  EXPECT_EQ(evict_one(p), 6u);
  EXPECT_EQ(evict_one(p), 5u);
  EXPECT_EQ(evict_one(p), 7u);
  EXPECT_FALSE(evict_one(p).has_value());
}

TEST(SchedulePolicyTest, ANewHintReplacesTheLastOneAndUnevictableBricksAreSkipped) {
  SchedulePolicy p;
  for (uint32_t b : {0u, 1u, 2u}) p.on_insert(b, 10, 0.1);
  const std::vector<uint32_t> first = {0, 1, 2};
  p.on_schedule_hint(first);
  const std::vector<uint32_t> second = {2, 1};  // 0 no longer needed
  p.on_schedule_hint(second);
  EXPECT_EQ(p.choose_victim([](uint32_t b) { return b != 0; }), 1u);  // 0 pinned: the latest of 2, 1
  EXPECT_EQ(p.choose_victim(testing_policy::any_brick), 0u);
  p.on_erase(0);
  p.on_erase(1);
  p.on_erase(2);
  EXPECT_TRUE(p.recency_order().empty());
  p.on_erase(9);  // untracked: a no-op
}

// On a known sequence with the whole future as the hint at every step, the
// policy makes OPT's choices: here it needs 5 builds where LRU needs 6.
TEST(SchedulePolicyTest, WithTheWholeFutureAsHintItMatchesBeladyOnUnitSizes) {
  const std::vector<uint32_t> sequence = {0, 1, 2, 0, 1, 3, 0, 1, 2, 3};
  auto builds = [&](EvictionPolicy& policy, bool hint) {
    std::vector<uint32_t> resident;
    int misses = 0;
    for (std::size_t i = 0; i < sequence.size(); ++i) {
      if (hint) policy.on_schedule_hint(std::span<const uint32_t>(sequence).subspan(i + 1));
      const uint32_t b = sequence[i];
      if (std::find(resident.begin(), resident.end(), b) != resident.end()) {
        policy.on_access(b);
        continue;
      }
      ++misses;
      if (resident.size() == 3) {
        const auto victim = policy.choose_victim(testing_policy::any_brick);
        EXPECT_TRUE(victim.has_value());
        policy.on_erase(*victim);
        resident.erase(std::find(resident.begin(), resident.end(), *victim));
      }
      resident.push_back(b);
      policy.on_insert(b, 1, 0.0);
    }
    return misses;
  };
  SchedulePolicy schedule;
  LruPolicy lru;
  EXPECT_EQ(builds(schedule, true), 5);
  EXPECT_EQ(builds(lru, false), 6);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
