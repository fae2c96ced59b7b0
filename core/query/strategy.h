// The strategies that answer a batch (chosen by batch_planner.h), each a
// function over one StrategyContext: what the batch reads and writes, named.
// Each returns an error (a brick that cannot be had) or CANCELLED; the
// answers are then incomplete.
//
// Thread-safety: one batch per context; the cache and proxies are shared
// with concurrent batches.
#pragma once

#include <cstdint>
#include <vector>

#include "core/cache/brick_cache.h"
#include "core/query/batch_scratch.h"
#include "core/query/brick_demand.h"
#include "core/query/proxy_gate.h"
#include "core/query/query_batch.h"
#include "core/query/query_engine.h"
#include "core/query/ray_walk.h"
#include "core/query/visit_stats.h"
#include "core/store/scene_store.h"
#include "core/util/status.h"

namespace outcore {

template <QueryKind kKind>
struct StrategyContext {
  const QueryBatch<kKind>& batch;
  const RayWalk<kKind>& walk;
  BrickCache& cache;
  const SceneStore& store;
  ProxyGate& gate;  // its view of resident bricks is updated between phases
  BrickDemand& demand;
  BatchScratch& scratch;
  const QueryOptions& options;
  uint64_t bricks_budget_holds;   // the budget over the average brick reservation
  CacheCounters counters_before;  // at the batch's start
  BatchTally& tally;

  uint32_t brick_count() const { return store.brick_count(); }
};

// The error a batch stopped by cancel_requested() returns.
Status batch_interrupted();

// One ray at a time, in input order, brick by brick.
template <QueryKind kKind>
Status run_sequential(StrategyContext<kKind>& ctx);
// Every brick pinned, one ResidentBrickSet over them, chunks of rays through it.
template <QueryKind kKind>
Status run_resident_set(StrategyContext<kKind>& ctx);
// Chunks of consecutive rays through all their (resident) bricks, round by
// round. `pinned`: bricks the caller already pinned for this batch (indexed
// by brick id, or empty), used as they are instead of acquired again.
template <QueryKind kKind>
Status run_in_cache_sweep(StrategyContext<kKind>& ctx, std::vector<PinnedBrick> pinned = {});
// Rays queued at bricks, resident bricks first, then builds of the longest queues.
template <QueryKind kKind>
Status run_queued(StrategyContext<kKind>& ctx);

}  // namespace outcore
