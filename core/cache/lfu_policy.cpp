#include "core/cache/lfu_policy.h"

#include <algorithm>

namespace outcore {

void LfuPolicy::place(uint32_t brick, uint64_t key) {
  if (brick >= slots_.size()) slots_.resize(brick + 1);
  Slot& slot = slots_[brick];
  if (slot.tracked) ranked_.erase({slot.key, slot.tick, brick});
  slot.tracked = true;
  slot.key = key;
  slot.tick = ++clock_;
  ranked_.emplace(slot.key, slot.tick, brick);
}

void LfuPolicy::on_insert(uint32_t brick, uint64_t /*bytes*/, double /*build_seconds*/) {
  place(brick, age_ + 1);
}

void LfuPolicy::on_access(uint32_t brick) {
  const bool tracked = brick < slots_.size() && slots_[brick].tracked;
  place(brick, tracked ? slots_[brick].key + 1 : age_ + 1);
}

void LfuPolicy::on_erase(uint32_t brick) {
  if (brick >= slots_.size() || !slots_[brick].tracked) return;
  Slot& slot = slots_[brick];
  ranked_.erase({slot.key, slot.tick, brick});
  // Erasing a brick that is not the cheapest (never done by the cache) must not
  // age the others backwards.
  age_ = std::max(age_, slot.key);
  slot = Slot{};
}

std::optional<uint32_t> LfuPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  for (const auto& [key, tick, brick] : ranked_) {
    if (evictable(brick)) return brick;
  }
  return std::nullopt;
}

uint64_t LfuPolicy::key(uint32_t brick) const {
  return brick < slots_.size() && slots_[brick].tracked ? slots_[brick].key : 0;
}

std::vector<uint32_t> LfuPolicy::order() const {
  std::vector<uint32_t> out;
  for (const auto& entry : ranked_) out.push_back(std::get<2>(entry));
  return out;
}

const std::string& LfuPolicy::name() const {
  static const std::string kName = "lfu";
  return kName;
}

}  // namespace outcore
