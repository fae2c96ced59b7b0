#include "core/cache/lru_policy.h"

#include <cassert>

namespace outcore {

void LruPolicy::link_front(uint32_t brick) {
  assert(brick != kNone);
  if (brick >= linked_.size()) {
    prev_.resize(brick + 1, kNone);
    next_.resize(brick + 1, kNone);
    linked_.resize(brick + 1, 0);
  }
  prev_[brick] = kNone;
  next_[brick] = head_;
  if (head_ != kNone) prev_[head_] = brick;
  head_ = brick;
  if (tail_ == kNone) tail_ = brick;
  linked_[brick] = 1;
  ++size_;
}

void LruPolicy::unlink(uint32_t brick) {
  const uint32_t before = prev_[brick];
  const uint32_t after = next_[brick];
  if (before != kNone)
    next_[before] = after;
  else
    head_ = after;
  if (after != kNone)
    prev_[after] = before;
  else
    tail_ = before;
  prev_[brick] = next_[brick] = kNone;
  linked_[brick] = 0;
  --size_;
}

void LruPolicy::on_insert(uint32_t brick, uint64_t /*bytes*/, double /*build_seconds*/) {
  if (tracked(brick)) unlink(brick);
  link_front(brick);
}

void LruPolicy::on_access(uint32_t brick) {
  if (tracked(brick)) {
    if (head_ == brick) return;
    unlink(brick);
  }
  link_front(brick);
}

void LruPolicy::on_erase(uint32_t brick) {
  if (tracked(brick)) unlink(brick);
}

std::optional<uint32_t> LruPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  for (uint32_t brick = tail_; brick != kNone; brick = prev_[brick]) {
    if (evictable(brick)) return brick;
  }
  return std::nullopt;
}

const std::string& LruPolicy::name() const {
  static const std::string kName = "lru";
  return kName;
}

std::vector<uint32_t> LruPolicy::order() const {
  std::vector<uint32_t> bricks;
  bricks.reserve(size_);
  for (uint32_t brick = tail_; brick != kNone; brick = prev_[brick]) bricks.push_back(brick);
  return bricks;
}

}  // namespace outcore
