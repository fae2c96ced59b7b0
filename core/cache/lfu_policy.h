// LfuPolicy ("lfu"): least frequently used with dynamic aging (LFU-DA; Arlitt
// et al. 2000). Each resident brick has a key = L + its hit count since it was
// inserted (an insert counts 1); the victim is the evictable brick with the
// smallest key, the least recently used among equal keys.
//
// Aging rule: L starts at 0 and, whenever a brick is evicted, becomes that
// brick's key. A newcomer therefore starts level with the last victim rather
// than below every brick that was hot long ago, so bricks that were popular in
// an earlier phase of a workload but are no longer hit age out once the
// newcomers' keys pass theirs. Counts are kept only while a brick is resident.
//
// Keys live in an ordered set: insert, access and erase are O(log n);
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

class LfuPolicy final : public EvictionPolicy {
 public:
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  void on_access(uint32_t brick) override;
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  uint64_t age() const { return age_; }  // L
  // The key of a tracked brick (L at insert + hits), 0 if untracked.
  uint64_t key(uint32_t brick) const;
  // Tracked bricks, next victim first (for tests).
  std::vector<uint32_t> order() const;

 private:
  struct Slot {
    bool tracked = false;
    uint64_t key = 0;
    uint64_t tick = 0;  // last insert or access, for LRU among equal keys
  };
  void place(uint32_t brick, uint64_t key);

  std::vector<Slot> slots_;
  std::set<std::tuple<uint64_t, uint64_t, uint32_t>> ranked_;  // (key, tick, brick)
  uint64_t age_ = 0;
  uint64_t clock_ = 0;
};

}  // namespace outcore
