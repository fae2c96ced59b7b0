// The sequential strategy (reordering off): for comparison, each ray walks
// its bricks on its own, in input order, taking each from the cache.
#include <span>

#include "core/query/brick_visit.h"
#include "core/query/strategy.h"
#include "core/util/cancellation.h"

namespace outcore {

Status batch_interrupted() {
  return cancelled("the batch was cancelled before all its rays were traced (the process is stopping)");
}

template <QueryKind kKind>
Status run_sequential(StrategyContext<kKind>& ctx) {
  const QueryBatch<kKind>& batch = ctx.batch;
  QueryStats& stats = ctx.tally.stats;
  std::vector<RayProgress>& progress = ctx.scratch.progress;
  for (std::size_t i = 0; i < batch.size(); ++i) {
    if (!batch.valid[i]) continue;
    if (cancel_requested()) return batch_interrupted();
    const uint32_t id = static_cast<uint32_t>(i);
    const auto t0 = Clock::now();
    VisitCounters counters;
    for (uint32_t brick = ctx.walk.start(progress[i], i, counters); brick != kInvalidId;
         brick = ctx.walk.advance(progress[i], i, counters)) {
      PinnedBrick pin;
      OUTCORE_RETURN_IF_ERROR(acquire_brick(ctx.cache, brick, 1, pin, ctx.tally));
      counters.visits_without_hit += batch.trace(pin.accel(), std::span<const uint32_t>(&id, 1));
      ++stats.brick_visits;
    }
    stats.rays_hit += batch.answered_hit(i);
    ctx.tally.add(counters);
    stats.seconds_brick += seconds_since(t0);
  }
  return Status::Ok();
}

template Status run_sequential(StrategyContext<QueryKind::kClosestHit>&);
template Status run_sequential(StrategyContext<QueryKind::kAnyHit>&);
template Status run_sequential(StrategyContext<QueryKind::kAllHits>&);

}  // namespace outcore
