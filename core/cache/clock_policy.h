// ClockPolicy ("clock"): CLOCK (second chance; Corbató 1968). Resident bricks
// sit on a circle in insertion order with one reference bit each. A new brick
// enters just behind the hand with its bit clear; a hit sets the bit. To choose
// a victim the hand sweeps from the oldest brick: a set bit is cleared and the
// brick passed over (it goes round again), the first evictable brick with a
// clear bit is the victim. Unevictable (pinned or building) bricks are passed
// over untouched.
//
// The circle is kept as a queue (BrickLists): "passing the hand over" a brick
// moves it to the newest end, which is the same order as a rotating hand. Each
// cleared bit was paid for by a hit, so choose_victim is amortised O(1) plus
// the pinned bricks it skips.
//
// Thread-safety: none of its own (see EvictionPolicy).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/cache/brick_lists.h"
#include "core/cache/eviction_policy.h"

namespace outcore {

class ClockPolicy final : public EvictionPolicy {
 public:
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  // Tracked bricks in the order the hand meets them (for tests).
  std::vector<uint32_t> order() const { return circle_.oldest_first(0); }
  bool referenced(uint32_t brick) const { return brick < referenced_.size() && referenced_[brick] != 0; }

 private:
  BrickLists<1> circle_;
  std::vector<uint8_t> referenced_;
};

}  // namespace outcore
