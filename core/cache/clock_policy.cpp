#include "core/cache/clock_policy.h"

namespace outcore {

void ClockPolicy::on_insert(uint32_t brick, uint64_t /*bytes*/, double /*build_seconds*/) {
  if (brick >= referenced_.size()) referenced_.resize(brick + 1, 0);
  circle_.move_to_front(0, brick);
  referenced_[brick] = 0;
}

void ClockPolicy::on_access(uint32_t brick) {
  if (!circle_.contains(brick)) {
    on_insert(brick, 0, 0.0);
    return;
  }
  referenced_[brick] = 1;
}

void ClockPolicy::on_erase(uint32_t brick) {
  if (circle_.contains(brick)) circle_.remove(brick);
}

std::optional<uint32_t> ClockPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  // A brick passed over with its bit set comes round once more with it clear,
  // so the sweep ends after at most two rounds.
  uint64_t steps = 2 * uint64_t{circle_.size(0)} + 1;
  for (uint32_t brick = circle_.back(0); brick != BrickLists<1>::kNone && steps > 0; --steps) {
    const uint32_t next = circle_.newer(brick);
    if (evictable(brick)) {
      if (!referenced_[brick]) return brick;
      referenced_[brick] = 0;
      circle_.move_to_front(0, brick);
      // Past the newest brick the hand wraps round to the oldest.
      brick = next == BrickLists<1>::kNone ? circle_.back(0) : next;
      continue;
    }
    brick = next;
  }
  return std::nullopt;
}

const std::string& ClockPolicy::name() const {
  static const std::string kName = "clock";
  return kName;
}

}  // namespace outcore
