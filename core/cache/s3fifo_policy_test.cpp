#include "core/cache/s3fifo_policy.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::any_brick;
using testing_policy::drain;
using testing_policy::evict_one;
using V = std::vector<uint32_t>;

TEST(S3FifoPolicyTest, OneHitWondersLeaveFromTheSmallQueueIntoTheGhost) {
  S3FifoPolicy s3;
  EXPECT_EQ(s3.name(), "s3fifo");
  s3.set_budget(1000);  // S target 100 bytes, ghost 900 bytes
  for (uint32_t b : {0u, 1u, 2u}) s3.on_insert(b, 100, 0.0);
  EXPECT_EQ(s3.queue(S3FifoPolicy::kSmall), (V{0, 1, 2}));
  s3.on_access(0);  // 0 was hit in S: promoted on the way out
  EXPECT_EQ(evict_one(s3), 1u);
  EXPECT_EQ(s3.queue(S3FifoPolicy::kMain), (V{0}));
  EXPECT_EQ(s3.count(0), 0u) << "counters are cleared on promotion";
  EXPECT_EQ(s3.queue(S3FifoPolicy::kGhost), (V{1}));
  // A ghost comes back straight into M.
  s3.on_insert(1, 100, 0.0);
  EXPECT_EQ(s3.queue(S3FifoPolicy::kMain), (V{0, 1}));
  EXPECT_TRUE(s3.queue(S3FifoPolicy::kGhost).empty());
}

TEST(S3FifoPolicyTest, MainQueueIsATwoBitClock) {
  S3FifoPolicy s3;
  s3.set_budget(10000);  // S target 1000: three 100-byte bricks never fill it
  // Put 0, 1, 2 in M through the ghost.
  for (uint32_t b : {0u, 1u, 2u}) s3.on_insert(b, 100, 0.0);
  // S below target and M empty: the victims come from S.
  EXPECT_EQ(drain(s3), (V{0, 1, 2}));
  for (uint32_t b : {0u, 1u, 2u}) s3.on_insert(b, 100, 0.0);
  EXPECT_EQ(s3.queue(S3FifoPolicy::kMain), (V{0, 1, 2}));
  s3.on_access(0);
  s3.on_access(0);
  s3.on_access(1);
  for (int i = 0; i < 5; ++i) s3.on_access(2);
  EXPECT_EQ(s3.count(2), S3FifoPolicy::kMaxCount);
  // 0 (count 2) and 1 (1) and 2 (3) are reinserted with one less each round;
  // 1 reaches 0 first.
  EXPECT_EQ(evict_one(s3), 1u);
  EXPECT_EQ(evict_one(s3), 0u);
  EXPECT_EQ(evict_one(s3), 2u);
  EXPECT_TRUE(s3.queue(S3FifoPolicy::kGhost).empty()) << "M evictions are not remembered";
}

TEST(S3FifoPolicyTest, EvictsFromMainWhileTheSmallQueueIsBelowTarget) {
  S3FifoPolicy s3;
  s3.set_budget(1000);  // S target 100
  s3.on_insert(0, 100, 0.0);
  EXPECT_EQ(evict_one(s3), 0u);
  s3.on_insert(0, 100, 0.0);  // M: 0
  s3.on_insert(1, 50, 0.0);   // S: 1 (50 bytes < 100)
  EXPECT_EQ(evict_one(s3), 0u);
  s3.on_insert(2, 60, 0.0);  // S: 1 2 (110 bytes >= 100)
  EXPECT_EQ(evict_one(s3), 1u);
}

TEST(S3FifoPolicyTest, GhostIsBoundedInBytes) {
  S3FifoPolicy s3;
  s3.set_budget(1000);  // ghost holds 900 bytes
  for (uint32_t b = 0; b < 30; ++b) {
    s3.on_insert(b, 100, 0.0);
    evict_one(s3);
  }
  EXPECT_EQ(s3.queue_bytes(S3FifoPolicy::kGhost), 900u);
  EXPECT_EQ(s3.queue(S3FifoPolicy::kGhost).front(), 21u);
}

TEST(S3FifoPolicyTest, SkipsPinnedBricks) {
  S3FifoPolicy s3;
  s3.set_budget(1000);
  for (uint32_t b : {0u, 1u, 2u}) s3.on_insert(b, 100, 0.0);
  EXPECT_EQ(s3.choose_victim([](uint32_t b) { return b != 0; }), 1u);
  EXPECT_FALSE(s3.choose_victim([](uint32_t) { return false; }).has_value());
  EXPECT_EQ(drain(s3), (V{0, 1, 2}));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
