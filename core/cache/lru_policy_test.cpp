#include "core/cache/lru_policy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <optional>
#include <set>
#include <vector>

#include "core/cache/eviction_policy.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

const auto kAny = [](uint32_t) { return true; };

// Evicts everything, returning the order the policy chose.
std::vector<uint32_t> drain(EvictionPolicy& policy) {
  std::vector<uint32_t> order;
  while (const std::optional<uint32_t> victim = policy.choose_victim(kAny)) {
    order.push_back(*victim);
    policy.on_erase(*victim);
  }
  return order;
}

TEST(LruPolicyTest, EmptyPolicyHasNoVictim) {
  LruPolicy lru;
  EXPECT_FALSE(lru.choose_victim(kAny).has_value());
  EXPECT_EQ(lru.size(), 0u);
  EXPECT_EQ(lru.name(), "lru");
}

TEST(LruPolicyTest, EvictsInInsertionOrderWithoutAccesses) {
  LruPolicy lru;
  for (uint32_t b : {5u, 1u, 9u, 0u}) lru.on_insert(b, 100, 0.0);
  EXPECT_EQ(lru.order(), (std::vector<uint32_t>{5, 1, 9, 0}));
  EXPECT_EQ(drain(lru), (std::vector<uint32_t>{5, 1, 9, 0}));
  EXPECT_EQ(lru.size(), 0u);
}

TEST(LruPolicyTest, AccessMakesMostRecentlyUsed) {
  LruPolicy lru;
  for (uint32_t b : {0u, 1u, 2u, 3u}) lru.on_insert(b, 1, 0.0);
  lru.on_access(0);  // 1 2 3 0
  lru.on_access(2);  // 1 3 0 2
  lru.on_access(2);  // unchanged (already most recent)
  lru.on_access(1);  // 3 0 2 1
  EXPECT_EQ(lru.order(), (std::vector<uint32_t>{3, 0, 2, 1}));
  ASSERT_EQ(lru.choose_victim(kAny), 3u);
  lru.on_erase(3);
  lru.on_insert(7, 1, 0.0);  // 0 2 1 7
  lru.on_access(0);          // 2 1 7 0
  EXPECT_EQ(drain(lru), (std::vector<uint32_t>{2, 1, 7, 0}));
}

TEST(LruPolicyTest, ChooseVictimDoesNotForgetTheBrick) {
  LruPolicy lru;
  lru.on_insert(4, 1, 0.0);
  lru.on_insert(8, 1, 0.0);
  EXPECT_EQ(lru.choose_victim(kAny), 4u);
  EXPECT_EQ(lru.choose_victim(kAny), 4u);  // only on_erase forgets
  EXPECT_EQ(lru.size(), 2u);
}

TEST(LruPolicyTest, SkipsUnevictableBricks) {
  LruPolicy lru;
  for (uint32_t b : {0u, 1u, 2u, 3u}) lru.on_insert(b, 1, 0.0);
  std::set<uint32_t> pinned = {0, 1};
  const auto unpinned = [&](uint32_t b) { return pinned.count(b) == 0; };
  EXPECT_EQ(lru.choose_victim(unpinned), 2u);
  pinned = {0, 1, 2, 3};
  EXPECT_FALSE(lru.choose_victim(unpinned).has_value());
  pinned = {0};
  EXPECT_EQ(lru.choose_victim(unpinned), 1u);
  EXPECT_EQ(lru.size(), 4u);
}

TEST(LruPolicyTest, EraseFromAnywhereKeepsTheOrder) {
  LruPolicy lru;
  for (uint32_t b = 0; b < 6; ++b) lru.on_insert(b, 1, 0.0);
  lru.on_erase(3);   // middle
  lru.on_erase(0);   // least recent end
  lru.on_erase(5);   // most recent end
  lru.on_erase(42);  // untracked: no-op
  EXPECT_EQ(lru.order(), (std::vector<uint32_t>{1, 2, 4}));
  lru.on_insert(3, 1, 0.0);  // back in, as most recent
  EXPECT_EQ(drain(lru), (std::vector<uint32_t>{1, 2, 4, 3}));
}

TEST(LruPolicyTest, ReinsertMovesInsteadOfDuplicating) {
  LruPolicy lru;
  lru.on_insert(1, 1, 0.0);
  lru.on_insert(2, 1, 0.0);
  lru.on_insert(1, 1, 0.0);
  EXPECT_EQ(lru.size(), 2u);
  EXPECT_EQ(drain(lru), (std::vector<uint32_t>{2, 1}));
}

TEST(LruPolicyTest, MatchesAReferenceOnARandomSequence) {
  LruPolicy lru;
  std::vector<uint32_t> reference;  // least recent first
  uint32_t state = 12345;
  const auto next = [&] { return state = state * 1664525u + 1013904223u; };
  for (int step = 0; step < 5000; ++step) {
    const uint32_t brick = (next() >> 8) % 64;
    const uint32_t op = (next() >> 8) % 4;
    const auto it = std::find(reference.begin(), reference.end(), brick);
    if (op == 0) {
      if (it != reference.end()) reference.erase(it);
      lru.on_erase(brick);
    } else if (op == 3 && !reference.empty()) {
      const uint32_t pinned = (next() >> 8) % 64;
      const auto unpinned = [&](uint32_t b) { return b != pinned; };
      const std::optional<uint32_t> victim = lru.choose_victim(unpinned);
      std::optional<uint32_t> expected;
      for (uint32_t b : reference) {
        if (b != pinned) {
          expected = b;
          break;
        }
      }
      ASSERT_EQ(victim, expected) << "step " << step;
    } else {
      if (it != reference.end()) reference.erase(it);
      reference.push_back(brick);
      if (op == 1)
        lru.on_insert(brick, 1, 0.0);
      else
        lru.on_access(brick);
    }
    ASSERT_EQ(lru.order(), reference) << "step " << step;
  }
}

TEST(EvictionPolicyFactoryTest, CreatesEveryKnownPolicyByName) {
  const std::vector<std::string> names = eviction_policy_names();
  ASSERT_FALSE(names.empty());
  for (const std::string& name : names) {
    auto policy = make_eviction_policy(name);
    ASSERT_TRUE(policy.ok()) << name << ": " << policy.status().to_string();
    EXPECT_EQ((*policy)->name(), name);
  }
  auto lru = make_eviction_policy("lru");
  ASSERT_TRUE(lru.ok());
  EXPECT_NE(dynamic_cast<LruPolicy*>(lru->get()), nullptr);
}

TEST(EvictionPolicyFactoryTest, UnknownNameIsNotFoundListingKnownOnes) {
  for (const std::string name : {"belady", "LRU", ""}) {
    auto policy = make_eviction_policy(name);
    ASSERT_FALSE(policy.ok()) << name;
    EXPECT_EQ(policy.status().code(), StatusCode::kNotFound);
    EXPECT_NE(policy.status().message().find("'" + name + "'"), std::string::npos)
        << policy.status().message();
    EXPECT_NE(policy.status().message().find("lru"), std::string::npos) << policy.status().message();
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
