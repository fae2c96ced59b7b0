// GdsfPolicy ("gdsf"): GreedyDual-Size-Frequency (Cherkasova 1998). Each
// resident brick has a priority H = L + frequency × cost / size, where cost is
// the brick's measured load+build seconds (what a miss on it costs again),
// size its accounted bytes and frequency its hit count since it was inserted
// (an insert counts 1). The victim is the evictable brick with the smallest
// H, the least recently used among equal ones; L (the inflation value) starts
// at 0 and becomes the victim's H on every eviction, which ages bricks that
// are no longer hit. Cheap-to-rebuild, large, rarely used bricks go first.
//
// A cost below 1 µs (a clock's resolution, or a trace without timings) counts
// as 1 µs so frequency and size still rank such bricks.
//
// H lives in an ordered set: insert, access and erase are O(log n);
// choose_victim is O(log n) plus the pinned bricks it skips.
//
// Thread-safety: none of its own (see EvictionPolicy).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "core/cache/eviction_policy.h"

namespace outcore {

class GdsfPolicy final : public EvictionPolicy {
 public:
  static constexpr double kMinCostSeconds = 1e-6;

  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  double inflation() const { return inflation_; }  // L
  // H of a tracked brick, 0 if untracked.
  double priority(uint32_t brick) const;
  // Tracked bricks, next victim first (for tests).
  std::vector<uint32_t> order() const;

 private:
  struct Slot {
    bool tracked = false;
    uint64_t frequency = 0;
    double cost_per_byte = 0;  // cost / size
    double priority = 0;
    uint64_t tick = 0;
  };
  void rank(uint32_t brick);

  std::vector<Slot> slots_;
  std::set<std::tuple<double, uint64_t, uint32_t>> ranked_;  // (H, tick, brick)
  double inflation_ = 0;
  uint64_t clock_ = 0;
};

}  // namespace outcore
