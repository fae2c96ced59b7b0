// BrickDemand: per brick, how many rays still have it ahead of them (in
// their window of upcoming bricks or in its queue), for a schedule-aware
// eviction policy (SchedulePolicy). Kept only when the policy uses hints;
// one relaxed atomic per window entry and one per traced chunk.
//
// Thread-safety: add() and sub() run concurrently (relaxed atomics).
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

namespace outcore {

class BrickDemand {
 public:
  BrickDemand(bool tracking, uint32_t brick_count)
      : tracking_(tracking), counts_(tracking ? brick_count : 0) {}

  bool tracking() const { return tracking_; }
  void add(uint32_t brick) { counts_[brick].fetch_add(1, std::memory_order_relaxed); }
  void sub(uint32_t brick, uint32_t rays = 1) { counts_[brick].fetch_sub(rays, std::memory_order_relaxed); }
  uint32_t of(uint32_t brick) const { return counts_[brick].load(std::memory_order_relaxed); }

 private:
  bool tracking_;
  std::vector<std::atomic<uint32_t>> counts_;
};

}  // namespace outcore
