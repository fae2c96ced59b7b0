// The resident-set strategy: every brick pinned for the batch (cache hits:
// all are resident), then one ResidentBrickSet over them all, offered by the
// brick structure; chunks of consecutive rays go through it as they would
// through one brick. No upper walk, so no per-brick statistics.
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <memory>
#include <span>
#include <vector>

#include "core/query/brick_visit.h"
#include "core/query/strategy.h"

namespace outcore {
namespace {

struct SetChunk {
  uint64_t traced = 0;
  uint64_t invalid = 0;
  uint64_t hit = 0;
};

// Chunk c of the batch through the set: one call for its valid rays.
template <QueryKind kKind>
SetChunk trace_chunk(const QueryBatch<kKind>& batch, const ResidentBrickSet& set, std::size_t c) {
  std::array<uint32_t, kSweepRays> ids;
  const std::size_t base = c * kSweepRays;
  const std::size_t size = std::min(batch.size() - base, kSweepRays);
  SetChunk chunk;
  std::size_t count = 0;
  for (std::size_t i = base; i < base + size; ++i) {
    if (batch.chunk_ray_valid(i, chunk.invalid)) ids[count++] = static_cast<uint32_t>(i);
  }
  const std::span<const uint32_t> traced(ids.data(), count);
  if constexpr (kKind == QueryKind::kClosestHit) {
    set.intersect(traced, batch.rays.data(), batch.hits);
  } else if constexpr (kKind == QueryKind::kAnyHit) {
    set.occluded(traced, batch.rays.data(), batch.occluded);
  }
  for (const uint32_t i : traced) chunk.hit += batch.answered_hit(i);
  chunk.traced = count;
  return chunk;
}

}  // namespace

template <QueryKind kKind>
Status run_resident_set(StrategyContext<kKind>& ctx) {
  // The engine turns the set off for every-hit batches (a set answers
  // closest and any hit only).
  if constexpr (kKind == QueryKind::kAllHits) return internal_error("resident set asked for every hit");
  const QueryBatch<kKind>& batch = ctx.batch;
  QueryStats& stats = ctx.tally.stats;
  const uint32_t brick_count = ctx.brick_count();
  std::vector<PinnedBrick> pins(brick_count);
  std::vector<const BrickAccel*> accels(brick_count);
  // In parallel: every brick is resident, but one may be rebuilt as a better
  // structure on acquisition (--brick-accel auto).
  std::vector<PinningTask> tasks(brick_count);
  const auto t_pin = Clock::now();
  tbb::parallel_for(uint32_t{0}, brick_count, [&](uint32_t b) {
    // Isolated: a build's own parallel loops must not pick up another
    // brick's acquisition, which could wait on a build suspended below it.
    tbb::this_task_arena::isolate([&] {
      if (auto pin = pin_for(ctx.cache, b, 0, tasks[b])) pins[b] = std::move(*pin);
    });
  });
  stats.seconds_build += seconds_since(t_pin);
  for (uint32_t b = 0; b < brick_count; ++b) {
    OUTCORE_RETURN_IF_ERROR(tasks[b].status);
    merge_task(tasks[b], ctx.tally);
    accels[b] = &pins[b].accel();
  }
  const auto t_set = Clock::now();
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<ResidentBrickSet> set,
                           ctx.cache.builder().make_resident_set(accels));
  if (set == nullptr) {
    // The builder offers sets but not for these bricks (auto, when they
    // chose different structures): the batch is swept through them instead.
    return run_in_cache_sweep(ctx, std::move(pins));
  }
  stats.seconds_upper += seconds_since(t_set);
  const auto t_trace = Clock::now();
  const std::size_t chunks = (batch.size() + kSweepRays - 1) / kSweepRays;
  std::vector<SetChunk> chunk_counts(chunks);
  tbb::parallel_for(std::size_t{0}, chunks,
                    [&](std::size_t c) { chunk_counts[c] = trace_chunk(batch, *set, c); });
  for (const SetChunk& chunk : chunk_counts) {
    stats.rays_in_brick_set += chunk.traced;
    if (!batch.validated_apart) stats.invalid_rays += chunk.invalid;
    stats.rays_hit += chunk.hit;
  }
  stats.seconds_brick += seconds_since(t_trace);
  return Status::Ok();
}

template Status run_resident_set(StrategyContext<QueryKind::kClosestHit>&);
template Status run_resident_set(StrategyContext<QueryKind::kAnyHit>&);
template Status run_resident_set(StrategyContext<QueryKind::kAllHits>&);

}  // namespace outcore
