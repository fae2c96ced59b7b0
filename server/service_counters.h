// The service's figures since start: requests answered, failed and cancelled,
// and the engine's figures summed over the requests answered (those
// OUTCORE_QUERY_STATS marks kYes in its server column). ServiceCounters is
// a snapshot; AtomicServiceCounters is what the handlers add to.
//
// Thread-safety: AtomicServiceCounters may be added to and read from any
// thread (relaxed atomics: each figure is exact, a snapshot need not be
// consistent across figures). ServiceCounters is a plain value.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

#include "core/query/query_stats.h"

namespace outcore::server {

struct ServiceCounters {
  uint64_t requests = 0;            // unary calls + stream chunks answered or refused
  uint64_t failed_requests = 0;     // cancelled ones included
  uint64_t cancelled_requests = 0;  // by the client, or by the drain after SIGTERM
  // Summed over the requests answered: the figures the server sums (rays,
  // rays_hit, invalid_rays, seconds_total, brick visits, ...); others stay 0.
  QueryStats answered;
};

class AtomicServiceCounters {
 public:
  // One request answered or refused.
  void count_request(bool failed, bool cancelled);
  // Adds an answered request's figures.
  void add_answered(const QueryStats& stats);
  ServiceCounters snapshot() const;

 private:
  std::atomic<uint64_t> requests_{0};
  std::atomic<uint64_t> failed_requests_{0};
  std::atomic<uint64_t> cancelled_requests_{0};
  // By the figure's place in the list; times in nanoseconds.
  std::array<std::atomic<uint64_t>, kQueryStatsFieldCount> answered_{};
};

}  // namespace outcore::server
