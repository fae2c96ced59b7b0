// SchedulePolicy ("schedule"): schedule-aware eviction, Belady's rule on the
// known part of the future. The engine knows which bricks its queued rays will
// need (each ray's window of upcoming bricks, core/query/ray_walk.h) and
// hands the cache that knowledge as a schedule hint (on_schedule_hint:
// bricks, soonest first). To choose a victim:
// - a resident brick absent from the hint is needed by no queued ray: evict
//   such a brick first, the least recently used of them (the unknown future
//   falls back to recency);
// - when every evictable brick is in the hint, evict the one needed latest
//   (furthest down the hint), as Belady's OPT would.
// Without any hint it is exactly LRU.
//
// Bricks are kept in one recency list (BrickLists) and the hint as a position
// per brick id, so hints cost O(hint length) and choose_victim walks the
// recency list once.
//
// Thread-safety: none of its own (see EvictionPolicy).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/cache/brick_lists.h"
#include "core/cache/eviction_policy.h"

namespace outcore {

class SchedulePolicy final : public EvictionPolicy {
 public:
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  void on_schedule_hint(std::span<const uint32_t> upcoming) override;
  bool wants_schedule_hint() const override { return true; }
  const std::string& name() const override;

  // Tracked bricks, least recently used first (for tests).
  std::vector<uint32_t> recency_order() const { return recency_.oldest_first(0); }

 private:
  static constexpr uint32_t kNotHinted = 0xffffffffu;
  uint32_t position(uint32_t brick) const {
    return brick < hint_position_.size() ? hint_position_[brick] : kNotHinted;
  }

  BrickLists<1> recency_;                // front: most recently used
  std::vector<uint32_t> hint_position_;  // per brick id: index in the last hint
  std::vector<uint32_t> hinted_;         // the last hint's bricks (to reset them)
};

}  // namespace outcore
