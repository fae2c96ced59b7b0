#include "core/cache/s3fifo_policy.h"

#include <algorithm>

namespace outcore {

void S3FifoPolicy::set_budget(uint64_t budget_bytes) {
  small_target_ = budget_bytes / 10;
  ghost_limit_ = budget_bytes - small_target_;
}

void S3FifoPolicy::push(Queue which, uint32_t brick, uint64_t bytes) {
  if (brick >= brick_bytes_.size()) {
    brick_bytes_.resize(brick + 1, 0);
    count_.resize(brick + 1, 0);
  }
  queues_.push_front(which, brick);
  brick_bytes_[brick] = bytes;
  bytes_[which] += bytes;
}

void S3FifoPolicy::drop(uint32_t brick) {
  bytes_[queues_.list_of(brick)] -= brick_bytes_[brick];
  queues_.remove(brick);
}

void S3FifoPolicy::on_insert(uint32_t brick, uint64_t bytes, double /*build_seconds*/) {
  const uint8_t where = queues_.list_of(brick);
  if (where == kSmall || where == kMain) {
    on_access(brick);  // already resident (the cache never does this)
    return;
  }
  Queue target = kSmall;
  if (where == kGhost) {
    drop(brick);
    target = kMain;
  }
  push(target, brick, bytes);
  count_[brick] = 0;
}

void S3FifoPolicy::on_access(uint32_t brick) {
  const uint8_t where = queues_.list_of(brick);
  if (where != kSmall && where != kMain) {
    on_insert(brick, 0, 0.0);
    return;
  }
  count_[brick] = static_cast<uint8_t>(std::min<int>(count_[brick] + 1, kMaxCount));
}

void S3FifoPolicy::on_erase(uint32_t brick) {
  const uint8_t where = queues_.list_of(brick);
  if (where != kSmall && where != kMain) return;
  const uint64_t bytes = brick_bytes_[brick];
  drop(brick);
  count_[brick] = 0;
  if (where == kSmall) {
    push(kGhost, brick, bytes);
    while (bytes_[kGhost] > ghost_limit_ && queues_.size(kGhost) > 0) drop(queues_.back(kGhost));
  }
}

std::optional<uint32_t> S3FifoPolicy::victim_from_small(const std::function<bool(uint32_t)>& evictable) {
  for (uint32_t b = queues_.back(kSmall); b != BrickLists<3>::kNone;) {
    const uint32_t next = queues_.newer(b);
    if (evictable(b)) {
      if (count_[b] == 0) return b;
      const uint64_t bytes = brick_bytes_[b];
      drop(b);
      push(kMain, b, bytes);
      count_[b] = 0;
    }
    b = next;
  }
  return std::nullopt;
}

std::optional<uint32_t> S3FifoPolicy::victim_from_main(const std::function<bool(uint32_t)>& evictable) {
  // A reinserted brick is met again after the others, one count lower, so the
  // walk ends within kMaxCount + 1 rounds.
  for (uint32_t b = queues_.back(kMain); b != BrickLists<3>::kNone;) {
    const uint32_t next = queues_.newer(b);
    if (!evictable(b)) {
      b = next;
      continue;
    }
    if (count_[b] == 0) return b;
    --count_[b];
    queues_.move_to_front(kMain, b);
    b = next == BrickLists<3>::kNone ? queues_.back(kMain) : next;  // wrap round
  }
  return std::nullopt;
}

std::optional<uint32_t> S3FifoPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  if (bytes_[kSmall] >= small_target_ || queues_.size(kMain) == 0) {
    if (auto victim = victim_from_small(evictable)) return victim;
  }
  if (auto victim = victim_from_main(evictable)) return victim;
  // M had nothing evictable: S's oldest unhit brick after all (its promotions
  // above may have emptied it).
  return victim_from_small(evictable);
}

const std::string& S3FifoPolicy::name() const {
  static const std::string kName = "s3fifo";
  return kName;
}

}  // namespace outcore
