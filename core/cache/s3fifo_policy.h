// S3FifoPolicy ("s3fifo"): S3-FIFO (Yang et al., SOSP 2023): a small FIFO S,
// a main FIFO M and a ghost FIFO G (evicted brick ids, no data). Each resident
// brick has a hit counter capped at 3.
//
// - Insert: a brick remembered in G goes to M (and leaves G); any other to S.
//   Counters start at 0. A hit increments the counter.
// - Victim: from S when S holds at least 10 % of the budget (or M has no
//   evictable brick), else from M.
//   From S, oldest first: a brick hit at least once while in S moves to M
//   with its counter cleared (quick demotion of one-hit wonders, promotion of
//   the rest); the first one never hit is the victim and, once erased, enters
//   G. From M, oldest first: a brick with a counter > 0 is reinserted at the
//   new end with its counter decremented (2-bit CLOCK); the first with 0 is the
//   victim. Evictions from M are not remembered.
//
// Variable sizes: S's 10 % and G's bound are bytes; G remembers up to 90 % of
// the budget's worth of bricks (the paper: as many entries as M), dropping
// the oldest first. Without set_budget the budget is unlimited: everything
// stays in S (S is never "full") until M is empty, and G is never trimmed.
//
// Every move is paid for by a hit or an insert, so choose_victim is amortised
// O(1) plus the pinned bricks it skips.
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

class S3FifoPolicy final : public EvictionPolicy {
 public:
  enum Queue : int { kSmall = 0, kMain = 1, kGhost = 2 };
  static constexpr uint8_t kMaxCount = 3;

  void set_budget(uint64_t budget_bytes) override;
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  // For tests: a queue's bricks, oldest first, its bytes, a brick's counter.
  std::vector<uint32_t> queue(Queue which) const { return queues_.oldest_first(which); }
  uint64_t queue_bytes(Queue which) const { return bytes_[which]; }
  uint8_t count(uint32_t brick) const { return brick < count_.size() ? count_[brick] : 0; }

 private:
  void push(Queue which, uint32_t brick, uint64_t bytes);
  void drop(uint32_t brick);
  std::optional<uint32_t> victim_from_small(const std::function<bool(uint32_t)>& evictable);
  std::optional<uint32_t> victim_from_main(const std::function<bool(uint32_t)>& evictable);

  BrickLists<3> queues_;
  std::vector<uint64_t> brick_bytes_;
  std::vector<uint8_t> count_;
  uint64_t bytes_[3] = {0, 0, 0};
  uint64_t small_target_ = UINT64_MAX;
  uint64_t ghost_limit_ = UINT64_MAX;
};

}  // namespace outcore
