#include "server/throughput_history.h"

namespace outcore::server {

void ThroughputHistory::record(Clock::time_point when, uint64_t rays_total) {
  std::lock_guard lock(mutex_);
  samples_.push_back({when, rays_total});
  while (samples_.size() > 2 && when - samples_.front().when > kKept) samples_.pop_front();
}

double ThroughputHistory::rays_per_second(std::chrono::seconds window) const {
  std::lock_guard lock(mutex_);
  if (samples_.size() < 2) return 0;
  const Sample& newest = samples_.back();
  const Sample* from = &samples_.front();
  for (auto it = samples_.rbegin() + 1; it != samples_.rend(); ++it) {
    if (newest.when - it->when >= window) {
      from = &*it;
      break;
    }
  }
  const double seconds = std::chrono::duration<double>(newest.when - from->when).count();
  if (seconds <= 0 || newest.rays_total < from->rays_total) return 0;
  return static_cast<double>(newest.rays_total - from->rays_total) / seconds;
}

}  // namespace outcore::server
