#include "core/cache/arc_policy.h"

#include <algorithm>

namespace outcore {

void ArcPolicy::set_budget(uint64_t budget_bytes) {
  capacity_ = std::max<uint64_t>(budget_bytes, 1);
}

void ArcPolicy::push(List which, uint32_t brick, uint64_t bytes) {
  if (brick >= brick_bytes_.size()) brick_bytes_.resize(brick + 1, 0);
  lists_.push_front(which, brick);
  brick_bytes_[brick] = bytes;
  bytes_[which] += bytes;
}

void ArcPolicy::drop(uint32_t brick) {
  bytes_[lists_.list_of(brick)] -= brick_bytes_[brick];
  lists_.remove(brick);
}

void ArcPolicy::trim_ghosts() {
  while (bytes_[kT1] + bytes_[kB1] > capacity_ && lists_.size(kB1) > 0) drop(lists_.back(kB1));
  while (bytes_[kT1] + bytes_[kT2] + bytes_[kB1] + bytes_[kB2] > 2 * capacity_ && lists_.size(kB2) > 0)
    drop(lists_.back(kB2));
}

void ArcPolicy::on_insert(uint32_t brick, uint64_t bytes, double /*build_seconds*/) {
  const uint8_t where = lists_.list_of(brick);
  if (where == kT1 || where == kT2) {
    // Already resident (the cache never does this): count it as a hit.
    drop(brick);
    push(kT2, brick, bytes);
    return;
  }
  const double b1 = static_cast<double>(bytes_[kB1]);
  const double b2 = static_cast<double>(bytes_[kB2]);
  const double s = static_cast<double>(bytes);
  if (where == kB1) {
    p_ = std::min(static_cast<double>(capacity_), p_ + s * std::max(1.0, b1 > 0 ? b2 / b1 : 1.0));
    drop(brick);
    push(kT2, brick, bytes);
  } else if (where == kB2) {
    p_ = std::max(0.0, p_ - s * std::max(1.0, b2 > 0 ? b1 / b2 : 1.0));
    drop(brick);
    push(kT2, brick, bytes);
  } else {
    push(kT1, brick, bytes);
  }
  trim_ghosts();
}

void ArcPolicy::on_access(uint32_t brick) {
  const uint8_t where = lists_.list_of(brick);
  if (where == kT1 || where == kT2) {
    const uint64_t bytes = brick_bytes_[brick];
    drop(brick);
    push(kT2, brick, bytes);
  } else {
    on_insert(brick, 0, 0.0);
  }
}

void ArcPolicy::on_erase(uint32_t brick) {
  const uint8_t where = lists_.list_of(brick);
  if (where != kT1 && where != kT2) return;
  const uint64_t bytes = brick_bytes_[brick];
  drop(brick);
  push(where == kT1 ? kB1 : kB2, brick, bytes);
  trim_ghosts();
}

std::optional<uint32_t> ArcPolicy::oldest_evictable(List which,
                                                    const std::function<bool(uint32_t)>& evictable) const {
  for (uint32_t b = lists_.back(which); b != BrickLists<4>::kNone; b = lists_.newer(b)) {
    if (evictable(b)) return b;
  }
  return std::nullopt;
}

std::optional<uint32_t> ArcPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  const bool from_t1 =
      lists_.size(kT1) > 0 && (static_cast<double>(bytes_[kT1]) > p_ || lists_.size(kT2) == 0);
  const List first = from_t1 ? kT1 : kT2;
  if (auto victim = oldest_evictable(first, evictable)) return victim;
  return oldest_evictable(first == kT1 ? kT2 : kT1, evictable);
}

const std::string& ArcPolicy::name() const {
  static const std::string kName = "arc";
  return kName;
}

}  // namespace outcore
