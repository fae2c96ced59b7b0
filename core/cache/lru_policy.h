// LruPolicy ("lru"): evicts the least recently used evictable brick. An insert
// and an access both make a brick the most recently used.
//
// Bricks are kept in an intrusive doubly linked list over arrays indexed by
// brick id (ids are dense), so insert, access and erase are O(1) with no
// allocation once the arrays have grown to the largest id; choose_victim walks
// from the least recently used end past unevictable (pinned or building) ones.
//
// Thread-safety: none of its own (see EvictionPolicy).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/cache/eviction_policy.h"

namespace outcore {

class LruPolicy final : public EvictionPolicy {
 public:
  // Tracks `brick` as the most recently used (an already tracked brick moves).
  void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) override;
  // Makes a tracked brick the most recently used; tracks an untracked one.
  void on_access(uint32_t brick) override;
  // Forgets `brick`; a no-op for an untracked one.
  void on_erase(uint32_t brick) override;
  std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) override;
  const std::string& name() const override;

  // Tracked bricks, least recently used first (for tests and reports).
  std::vector<uint32_t> order() const;
  uint32_t size() const { return size_; }

 private:
  static constexpr uint32_t kNone = 0xffffffffu;
  bool tracked(uint32_t brick) const { return brick < linked_.size() && linked_[brick] != 0; }
  void link_front(uint32_t brick);
  void unlink(uint32_t brick);

  // prev_ points towards the most recently used end (head_), next_ towards the
  // least recently used end (tail_).
  std::vector<uint32_t> prev_;
  std::vector<uint32_t> next_;
  std::vector<uint8_t> linked_;
  uint32_t head_ = kNone;  // most recently used
  uint32_t tail_ = kNone;  // least recently used
  uint32_t size_ = 0;
};

}  // namespace outcore
