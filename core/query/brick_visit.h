// The brick visit step: taking a brick from the cache, tracing the rays
// queued there, and moving each on to its next brick.
//
// Thread-safety: trace_and_advance() runs concurrently on disjoint rays;
// acquire_brick() adds to the batch's tally and must be serialised by the
// caller; pin_for() writes only its task.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "core/cache/brick_cache.h"
#include "core/query/ray_walk.h"
#include "core/query/visit_stats.h"
#include "core/util/status.h"

namespace outcore {

// Rays per task when tracing inside a brick.
constexpr std::size_t kRayGrain = 512;
// How many rays ahead trace_and_advance() prefetches per-ray state.
constexpr std::size_t kAdvancePrefetch = 8;

// (next brick, ray) pairs a task hands to the scheduler.
using MovedRays = std::vector<std::pair<uint32_t, uint32_t>>;

// Takes `brick` from the cache into `pin` for `rays` rays (0: not known;
// BrickCache::acquire), counting the acquisition and the wait in `tally`.
Status acquire_brick(BrickCache& cache, uint32_t brick, uint64_t rays, PinnedBrick& pin, BatchTally& tally,
                     uint64_t rays_ahead = 0);

// What a parallel task that takes a brick from the cache reports.
struct PinningTask {
  VisitCounters counters;
  double build_seconds = 0;
  bool was_hit = false;
  Status status;
};

// Takes `brick` from the cache for `task` to trace `rays` rays; nullopt
// (the error kept in the task) when it cannot be had.
std::optional<PinnedBrick> pin_for(BrickCache& cache, uint32_t brick, uint64_t rays, PinningTask& task,
                                   uint64_t rays_ahead = 0);

// Adds a finished task's figures to the batch's (in task order).
inline void merge_task(const PinningTask& task, BatchTally& tally) {
  tally.add(task.counters);
  tally.add_acquisition(task.was_hit);
}

// Moves each of the rays `ids`, done with `brick`, to its next brick,
// collecting (next brick, ray) in `moved` for the scheduler.
template <QueryKind kKind>
void advance_past(const RayWalk<kKind>& walk, RayProgress* progress, uint32_t brick,
                  std::span<const uint32_t> ids, VisitCounters& counters, MovedRays& moved) {
  const QueryBatch<kKind>& batch = walk.batch;
  if (walk.demand.tracking()) walk.demand.sub(brick, static_cast<uint32_t>(ids.size()));
  for (std::size_t k = 0; k < ids.size(); ++k) {
    if (k + kAdvancePrefetch < ids.size()) {
      // A queue's rays are scattered over the batch: advance() would
      // otherwise stall on each ray's progress record.
      const uint32_t ahead = ids[k + kAdvancePrefetch];
      __builtin_prefetch(&progress[ahead]);
      __builtin_prefetch(reinterpret_cast<const char*>(&progress[ahead]) + sizeof(RayProgress) - 1);
      if constexpr (kKind == QueryKind::kClosestHit) __builtin_prefetch(&batch.hits[ahead].t);
    }
    const uint32_t ray = ids[k];
    const uint32_t next = walk.advance(progress[ray], ray, counters);
    if (next != kInvalidId) {
      moved.emplace_back(next, ray);
    } else {
      // A ray with a brick finishes here, once, after its last brick (a ray
      // without one, or an invalid one, cannot hit): counted while its
      // answer is in the cache, not by a pass over the batch's hits.
      counters.rays_hit += batch.answered_hit(ray);
    }
  }
}

// Traces the rays `ids` queued at `brick` there, then advance_past().
template <QueryKind kKind>
void trace_and_advance(const RayWalk<kKind>& walk, RayProgress* progress, uint32_t brick,
                       const BrickAccel& accel, std::span<const uint32_t> ids, VisitCounters& counters,
                       MovedRays& moved) {
  counters.visits_without_hit += walk.batch.trace(accel, ids);
  advance_past(walk, progress, brick, ids, counters, moved);
}

}  // namespace outcore
