#include "core/cache/schedule_policy.h"

namespace outcore {

void SchedulePolicy::on_insert(uint32_t brick, uint64_t /*bytes*/, double /*build_seconds*/) {
  recency_.move_to_front(0, brick);
}

void SchedulePolicy::on_access(uint32_t brick) {
  if (recency_.front(0) != brick) recency_.move_to_front(0, brick);
}

void SchedulePolicy::on_erase(uint32_t brick) {
  if (recency_.contains(brick)) recency_.remove(brick);
}

void SchedulePolicy::on_schedule_hint(std::span<const uint32_t> upcoming) {
  for (const uint32_t brick : hinted_) hint_position_[brick] = kNotHinted;
  hinted_.clear();
  for (std::size_t i = 0; i < upcoming.size(); ++i) {
    const uint32_t brick = upcoming[i];
    if (brick >= hint_position_.size()) hint_position_.resize(brick + 1, kNotHinted);
    // A brick listed twice keeps its soonest position.
    if (hint_position_[brick] != kNotHinted) continue;
    hint_position_[brick] = static_cast<uint32_t>(i);
    hinted_.push_back(brick);
  }
}

std::optional<uint32_t> SchedulePolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  std::optional<uint32_t> latest;
  uint32_t latest_position = 0;
  for (uint32_t brick = recency_.back(0); brick != BrickLists<1>::kNone; brick = recency_.newer(brick)) {
    if (!evictable(brick)) continue;
    const uint32_t p = position(brick);
    if (p == kNotHinted) return brick;  // needed by no queued ray
    if (!latest || p > latest_position) {
      latest = brick;
      latest_position = p;
    }
  }
  return latest;
}

const std::string& SchedulePolicy::name() const {
  static const std::string kName = "schedule";
  return kName;
}

}  // namespace outcore
