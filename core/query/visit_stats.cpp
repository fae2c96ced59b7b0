#include "core/query/visit_stats.h"

namespace outcore {

void BatchTally::add(const VisitCounters& counters) {
  stats.rays_hit += counters.rays_hit;
  stats.invalid_rays += counters.invalid_rays;
  stats.upper_nodes_visited += counters.nodes;
  stats.brick_visits += counters.ahead_visits;
  stats.brick_visits_without_hit += counters.visits_without_hit;
  stats.rays_traced_ahead += counters.ahead_traces;
  stats.proxy_tests += counters.proxy_tests;
  stats.bricks_skipped_by_proxy += counters.skipped;
  stats.bricks_skipped_by_bound += counters.skipped_by_bound;
  stats.rays_entering_no_brick += counters.no_brick;
  proxy_ticks += counters.proxy_ticks;
}

void BatchTally::add_acquisition(bool was_hit) {
  ++stats.brick_acquisitions;
  ++(was_hit ? stats.cache_hits : stats.cache_misses);
}

void finish_batch_stats(BatchTally& tally, const BrickCache& cache, const CacheCounters& before,
                        Clock::time_point start, uint64_t ticks_start, const ProxySet* proxies) {
  QueryStats& stats = tally.stats;
  const CacheCounters after = cache.counters();
  stats.brick_builds = after.builds - before.builds;
  stats.brick_rebuilds = after.rebuilds - before.rebuilds;
#define OUTCORE_SET_STRUCTURE_BUILDS(type, name, object, key, ...)                               \
  {                                                                                              \
    const std::size_t structure = brick_structure_index(key);                                    \
    if (structure < kMaxBrickStructures)                                                         \
      stats.name = after.builds_by_structure[structure] - before.builds_by_structure[structure]; \
  }
  OUTCORE_STRUCTURE_BUILDS(OUTCORE_SET_STRUCTURE_BUILDS)
#undef OUTCORE_SET_STRUCTURE_BUILDS
  stats.evictions = after.evictions - before.evictions;
  const SubtreeTierCounters& tier_before = before.subtree;
  const SubtreeTierCounters& tier_after = after.subtree;
  stats.subtree_loads = tier_after.loads - tier_before.loads;
  stats.subtree_loads_checked = tier_after.loads_checked - tier_before.loads_checked;
  stats.subtree_loads_kept = tier_after.loads_kept - tier_before.loads_kept;
  stats.subtree_loads_recycled = tier_after.loads_recycled - tier_before.loads_recycled;
  stats.subtree_writes = tier_after.writes - tier_before.writes;
  stats.subtree_rejects = tier_after.rejected() - tier_before.rejected();
  stats.subtree_bytes_read = tier_after.bytes_read - tier_before.bytes_read;
  stats.subtree_bytes_written = tier_after.bytes_written - tier_before.bytes_written;
  stats.seconds_brick_builds = after.build_seconds - before.build_seconds;
  stats.seconds_subtree_loads = tier_after.load_seconds - tier_before.load_seconds;
  stats.peak_bytes_resident = after.peak_resident_bytes;
  stats.cache_budget_bytes = cache.budget_bytes();
  stats.seconds_total = seconds_since(start);
  if (proxies != nullptr) {
    stats.proxy_bytes = proxies->memory_bytes();
    const uint64_t elapsed_ticks = ticks() - ticks_start;
    if (elapsed_ticks > 0) stats.seconds_proxy = stats.seconds_total * tally.proxy_ticks / elapsed_ticks;
  }
}

}  // namespace outcore
