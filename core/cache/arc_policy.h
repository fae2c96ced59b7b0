// ArcPolicy ("arc"): Adaptive Replacement Cache (Megiddo & Modha, FAST 2003),
// measured in bytes. Resident bricks are in T1 (seen once since they entered)
// or T2 (hit at least once, or readmitted from a ghost list); evicted bricks
// are remembered, without data, in the ghost lists B1 (evicted from T1) and B2
// (evicted from T2). All four are LRU lists. p is the target size of T1.
//
// - A hit moves the brick to the most recent end of T2.
// - A brick inserted while in B1 means T1 was too small: p grows by its bytes
//   × max(1, |B2|/|B1|) (capped at the budget c); one in B2 shrinks p by its
//   bytes × max(1, |B1|/|B2|) (floored at 0). Either way it enters T2. Any
//   other brick enters T1.
// - Victim (REPLACE): the least recent evictable brick of T1 if T1 holds more
//   than p bytes (or T2 is empty), else of T2; if that list has no evictable
//   brick, the other list's.
// - Ghost lists are trimmed, oldest first, so that |T1| + |B1| <= c and
//   |T1| + |T2| + |B1| + |B2| <= 2c.
//
// Variable sizes: all |X| and p are bytes (the original counts pages; a brick
// of s bytes moves p by s times the ratio, as s unit pages would). Because the
// cache evicts before it inserts, the adaptation of p happens at the insert,
// after the room was made; the original's tie rule for a B2 hit when |T1| = p
// is therefore not applied. Without set_budget, c is unlimited (ghosts are
// never trimmed).
//
// All operations are O(1) plus the pinned bricks choose_victim skips.
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

class ArcPolicy final : public EvictionPolicy {
 public:
  enum List : int { kT1 = 0, kT2 = 1, kB1 = 2, kB2 = 3 };

  void set_budget(uint64_t budget_bytes) override;
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  // For tests: a list's bricks, least recent first, its bytes, and p.
  std::vector<uint32_t> list(List which) const { return lists_.oldest_first(which); }
  uint64_t list_bytes(List which) const { return bytes_[which]; }
  double target_t1() const { return p_; }

 private:
  void push(List which, uint32_t brick, uint64_t bytes);
  void drop(uint32_t brick);
  void trim_ghosts();
  std::optional<uint32_t> oldest_evictable(List which, const std::function<bool(uint32_t)>& evictable) const;

  BrickLists<4> lists_;
  std::vector<uint64_t> brick_bytes_;
  uint64_t bytes_[4] = {0, 0, 0, 0};
  double p_ = 0;
  uint64_t capacity_ = UINT64_MAX / 4;
};

}  // namespace outcore
