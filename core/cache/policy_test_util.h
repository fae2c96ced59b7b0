// Helpers shared by the eviction policy unit tests.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "core/cache/eviction_policy.h"

namespace outcore::testing_policy {

inline bool any_brick(uint32_t) {
  return true;
}

// Evicts everything, returning the order the policy chose.
inline std::vector<uint32_t> drain(EvictionPolicy& policy) {
  std::vector<uint32_t> order;
  while (const std::optional<uint32_t> victim = policy.choose_victim(any_brick)) {
    order.push_back(*victim);
    policy.on_erase(*victim);
  }
  return order;
}

// Evicts one brick, returning it (or nothing).
inline std::optional<uint32_t> evict_one(EvictionPolicy& policy) {
  const std::optional<uint32_t> victim = policy.choose_victim(any_brick);
  if (victim) policy.on_erase(*victim);
  return victim;
}

}  // namespace outcore::testing_policy
