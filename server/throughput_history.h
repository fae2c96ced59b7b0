// ThroughputHistory: the recent rate of rays answered, for the status page.
// The server's main loop records the running ray total once a second; the
// page asks for the rate over the last N seconds.
//
// Thread-safety: record() and rays_per_second() may be called from any
// thread (one mutex; a handful of calls a second).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>

namespace outcore::server {

class ThroughputHistory {
 public:
  using Clock = std::chrono::steady_clock;

  // Samples older than this are dropped.
  static constexpr std::chrono::seconds kKept{600};

  void record(Clock::time_point when, uint64_t rays_total);
  // Rays per second between the newest sample and the newest one at least
  // `window` older (or the oldest kept); 0 with fewer than two samples.
  double rays_per_second(std::chrono::seconds window) const;

 private:
  struct Sample {
    Clock::time_point when;
    uint64_t rays_total;
  };
  mutable std::mutex mutex_;
  std::deque<Sample> samples_;  // oldest first
};

}  // namespace outcore::server
