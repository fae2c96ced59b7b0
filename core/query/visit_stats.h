// Visit statistics: what advancing rays counts per task (VisitCounters), and
// BatchTally, the batch's QueryStats being summed from those counters and
// from the brick acquisitions; finish_batch_stats() adds the cache-wide
// figures at the end. Every sum into QueryStats is here (visit_stats.cpp).
//
// Also the batch's clocks: a steady clock for phases and a cheap tick counter
// for calls too short to time with it (proxy tests).
//
// Thread-safety: counters are per task; a tally is summed on one thread.
#pragma once

#if defined(__x86_64__) || defined(__i386__)
#include <x86intrin.h>
#endif

#include <chrono>
#include <cstdint>

#include "core/cache/brick_cache.h"
#include "core/proxy/proxy_set.h"
#include "core/query/query_stats.h"

namespace outcore {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// The time-stamp counter where there is one (converted to seconds against
// the steady clock over the whole batch), else the steady clock.
inline uint64_t ticks() {
#if defined(__x86_64__) || defined(__i386__)
  return __rdtsc();
#else
  return static_cast<uint64_t>(Clock::now().time_since_epoch().count());
#endif
}

// What advancing rays counts, per task (merged in task order).
struct VisitCounters {
  uint64_t nodes = 0;
  uint64_t proxy_tests = 0;
  uint64_t skipped = 0;           // by the proxy
  uint64_t skipped_by_bound = 0;  // by the brick bound (--brick-bounds)
  uint64_t proxy_ticks = 0;
  uint64_t ahead_visits = 0;  // visits whose tracing was done ahead of time
  uint64_t visits_without_hit = 0;
  uint64_t ahead_traces = 0;
  uint64_t rays_hit = 0;      // rays finished with a hit (queued path)
  uint64_t invalid_rays = 0;  // found invalid in the queued path's first pass
  uint64_t no_brick = 0;      // valid rays whose walk found no brick (RayWalk::start)
};

// The batch's figures as it runs.
struct BatchTally {
  QueryStats stats;
  uint64_t proxy_ticks = 0;  // proxy tests, summed over tasks

  void add(const VisitCounters& counters);
  // One brick taken from the cache (found ready or not).
  void add_acquisition(bool was_hit);
};

// The cache-wide deltas since `before`, the budget and peak, the total time
// and the proxies' share of it.
void finish_batch_stats(BatchTally& tally, const BrickCache& cache, const CacheCounters& before,
                        Clock::time_point start, uint64_t ticks_start, const ProxySet* proxies);

}  // namespace outcore
