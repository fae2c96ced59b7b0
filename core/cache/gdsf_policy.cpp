#include "core/cache/gdsf_policy.h"

#include <algorithm>

namespace outcore {

void GdsfPolicy::rank(uint32_t brick) {
  Slot& slot = slots_[brick];
  slot.priority = inflation_ + static_cast<double>(slot.frequency) * slot.cost_per_byte;
  slot.tick = ++clock_;
  ranked_.emplace(slot.priority, slot.tick, brick);
}

void GdsfPolicy::on_insert(uint32_t brick, uint64_t bytes, double build_seconds) {
  if (brick >= slots_.size()) slots_.resize(brick + 1);
  Slot& slot = slots_[brick];
  if (slot.tracked) ranked_.erase({slot.priority, slot.tick, brick});
  slot.tracked = true;
  slot.frequency = 1;
  slot.cost_per_byte =
      std::max(build_seconds, kMinCostSeconds) / static_cast<double>(std::max<uint64_t>(bytes, 1));
  rank(brick);
}

void GdsfPolicy::on_access(uint32_t brick) {
  if (brick >= slots_.size() || !slots_[brick].tracked) {
    on_insert(brick, 1, 0.0);
    return;
  }
  Slot& slot = slots_[brick];
  ranked_.erase({slot.priority, slot.tick, brick});
  ++slot.frequency;
  rank(brick);
}

void GdsfPolicy::on_erase(uint32_t brick) {
  if (brick >= slots_.size() || !slots_[brick].tracked) return;
  Slot& slot = slots_[brick];
  ranked_.erase({slot.priority, slot.tick, brick});
  inflation_ = std::max(inflation_, slot.priority);
  slot = Slot{};
}

std::optional<uint32_t> GdsfPolicy::choose_victim(const std::function<bool(uint32_t)>& evictable) {
  for (const auto& [priority, tick, brick] : ranked_) {
    if (evictable(brick)) return brick;
  }
  return std::nullopt;
}

double GdsfPolicy::priority(uint32_t brick) const {
  return brick < slots_.size() && slots_[brick].tracked ? slots_[brick].priority : 0.0;
}

std::vector<uint32_t> GdsfPolicy::order() const {
  std::vector<uint32_t> out;
  for (const auto& entry : ranked_) out.push_back(std::get<2>(entry));
  return out;
}

const std::string& GdsfPolicy::name() const {
  static const std::string kName = "gdsf";
  return kName;
}

}  // namespace outcore
