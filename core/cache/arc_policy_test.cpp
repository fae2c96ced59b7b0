#include "core/cache/arc_policy.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/cache/policy_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing_policy::any_brick;
using testing_policy::drain;
using testing_policy::evict_one;
using V = std::vector<uint32_t>;

TEST(ArcPolicyTest, NewBricksEnterT1AndHitsMoveThemToT2) {
  ArcPolicy arc;
  EXPECT_EQ(arc.name(), "arc");
  arc.set_budget(400);
  for (uint32_t b : {0u, 1u, 2u}) arc.on_insert(b, 100, 0.0);
  arc.on_access(1);
  EXPECT_EQ(arc.list(ArcPolicy::kT1), (V{0, 2}));
  EXPECT_EQ(arc.list(ArcPolicy::kT2), (V{1}));
  EXPECT_EQ(arc.list_bytes(ArcPolicy::kT1), 200u);
  // p = 0 < |T1|: T1's least recent goes first, and is remembered in B1.
  EXPECT_EQ(evict_one(arc), 0u);
  EXPECT_EQ(arc.list(ArcPolicy::kB1), (V{0}));
  EXPECT_EQ(evict_one(arc), 2u);
  EXPECT_EQ(evict_one(arc), 1u);  // T1 empty: from T2
  EXPECT_EQ(arc.list(ArcPolicy::kB2), (V{1}));
}

TEST(ArcPolicyTest, AGhostHitInB1GrowsTheRecencySide) {
  ArcPolicy arc;
  arc.set_budget(300);
  for (uint32_t b : {0u, 1u, 2u}) arc.on_insert(b, 100, 0.0);
  arc.on_access(2);               // T1: 0 1, T2: 2
  EXPECT_EQ(evict_one(arc), 0u);  // B1: 0
  arc.on_insert(0, 100, 0.0);     // a B1 ghost hit: p += 100 * max(1, 0/100)
  EXPECT_DOUBLE_EQ(arc.target_t1(), 100.0);
  EXPECT_EQ(arc.list(ArcPolicy::kT2), (V{2, 0}));
  EXPECT_TRUE(arc.list(ArcPolicy::kB1).empty());
  // |T1| = 100 is not above p = 100: the victim now comes from T2.
  EXPECT_EQ(evict_one(arc), 2u);
  EXPECT_EQ(arc.list(ArcPolicy::kB2), (V{2}));
  // A B2 ghost hit shrinks p again: 100 - 100 * max(1, 0/100) = 0.
  arc.on_insert(2, 100, 0.0);
  EXPECT_DOUBLE_EQ(arc.target_t1(), 0.0);
  EXPECT_EQ(arc.list(ArcPolicy::kT2), (V{0, 2}));
  EXPECT_EQ(evict_one(arc), 1u);  // |T1| = 100 > p = 0
}

TEST(ArcPolicyTest, ScanResistance) {
  // Hot bricks in T2 survive a long scan of one-time bricks (which churn T1).
  ArcPolicy arc;
  arc.set_budget(400);
  for (uint32_t b : {0u, 1u}) {
    arc.on_insert(b, 100, 0.0);
    arc.on_access(b);
  }
  for (uint32_t scan = 10; scan < 40; ++scan) {
    const uint64_t resident = arc.list_bytes(ArcPolicy::kT1) + arc.list_bytes(ArcPolicy::kT2);
    if (resident + 100 > 400) {
      const auto victim = evict_one(arc);
      ASSERT_TRUE(victim.has_value());
      EXPECT_GE(*victim, 10u) << "a hot brick was evicted by the scan";
    }
    arc.on_insert(scan, 100, 0.0);
  }
  EXPECT_EQ(arc.list(ArcPolicy::kT2), (V{0, 1}));
}

TEST(ArcPolicyTest, GhostListsAreBoundedInBytes) {
  ArcPolicy arc;
  arc.set_budget(300);
  for (uint32_t b = 0; b < 50; ++b) {
    if (arc.list_bytes(ArcPolicy::kT1) + arc.list_bytes(ArcPolicy::kT2) + 100 > 300) evict_one(arc);
    arc.on_insert(b, 100, 0.0);
    if (b % 3 == 0) arc.on_access(b);
    const uint64_t t1 = arc.list_bytes(ArcPolicy::kT1), t2 = arc.list_bytes(ArcPolicy::kT2);
    const uint64_t b1 = arc.list_bytes(ArcPolicy::kB1), b2 = arc.list_bytes(ArcPolicy::kB2);
    EXPECT_LE(t1 + b1, 300u) << b;
    EXPECT_LE(t1 + t2 + b1 + b2, 600u) << b;
  }
}

TEST(ArcPolicyTest, SkipsPinnedBricksAndFallsBackToTheOtherList) {
  ArcPolicy arc;
  arc.set_budget(1000);
  arc.on_insert(0, 100, 0.0);
  arc.on_insert(1, 100, 0.0);
  arc.on_insert(2, 100, 0.0);
  arc.on_access(2);  // T1: 0 1, T2: 2
  EXPECT_EQ(arc.choose_victim([](uint32_t b) { return b != 0; }), 1u);
  EXPECT_EQ(arc.choose_victim([](uint32_t b) { return b == 2; }), 2u);
  EXPECT_FALSE(arc.choose_victim([](uint32_t) { return false; }).has_value());
  EXPECT_EQ(drain(arc), (V{0, 1, 2}));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
