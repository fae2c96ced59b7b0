// The in-cache sweep: when every brick is resident and the budget holds the
// scene (nothing can be evicted), queueing the whole batch at bricks buys no
// reuse; each task instead takes a chunk of consecutive rays through all
// their bricks, round by round, with the chunk's per-ray state kept in the
// thread's cache. Each ray visits the same bricks in the same order with the
// same hit so far, so answers are the same as queued.
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <mutex>
#include <span>
#include <vector>

#include "core/query/brick_visit.h"
#include "core/query/strategy.h"

namespace outcore {
namespace {

// Each brick is pinned by the first task to reach it and held to the end of
// the batch (a cache hit: all are resident); one lock per brick per batch,
// never per ray.
class SweepPins {
 public:
  SweepPins(BrickCache& cache, BatchTally& tally, uint32_t brick_count, std::vector<PinnedBrick> pinned)
      : cache_(cache), tally_(tally), pins_(std::move(pinned)), pinned_(brick_count), rays_(brick_count) {
    if (pins_.empty()) pins_.resize(brick_count);
    assert(pins_.size() == brick_count);
    for (uint32_t b = 0; b < brick_count; ++b)
      if (pins_[b].pinned()) pinned_[b].store(&pins_[b].accel(), std::memory_order_relaxed);
  }

  // Rays traced in `brick` (one relaxed add per group of rays, not per ray),
  // handed to the cache by report_rays() as the bricks' use.
  void note_rays(uint32_t brick, std::size_t rays) {
    rays_[brick].fetch_add(rays, std::memory_order_relaxed);
  }
  void report_rays() {
    std::vector<uint64_t> rays(rays_.size());
    for (std::size_t b = 0; b < rays.size(); ++b) rays[b] = rays_[b].load(std::memory_order_relaxed);
    cache_.add_rays_served(rays);
  }

  // The brick's accel, pinned on first need; nullptr when it cannot be had
  // (the error is kept for status()).
  const BrickAccel* accel(uint32_t brick) {
    const BrickAccel* accel = pinned_[brick].load(std::memory_order_acquire);
    if (accel != nullptr) return accel;
    std::lock_guard<std::mutex> lock(mutex_);
    accel = pinned_[brick].load(std::memory_order_relaxed);
    if (accel != nullptr) return accel;
    // Isolated: should another batch have evicted the brick, its build must
    // not pick up one of this batch's tasks, which could wait on this lock.
    const Status status =
        tbb::this_task_arena::isolate([&] { return acquire_brick(cache_, brick, 0, pins_[brick], tally_); });
    if (!status.ok()) {
      if (status_.ok()) status_ = status;
      failed_.store(true, std::memory_order_relaxed);
      return nullptr;
    }
    accel = &pins_[brick].accel();
    pinned_[brick].store(accel, std::memory_order_release);
    return accel;
  }
  bool failed() const { return failed_.load(std::memory_order_relaxed); }
  const Status& status() const { return status_; }

 private:
  BrickCache& cache_;
  BatchTally& tally_;
  std::vector<PinnedBrick> pins_;
  std::vector<std::atomic<const BrickAccel*>> pinned_;
  std::vector<std::atomic<uint64_t>> rays_;
  std::mutex mutex_;
  Status status_;
  std::atomic<bool> failed_{false};
};

struct SweepTask {
  VisitCounters counters;
  uint64_t visits = 0;
  uint64_t ticks = 0;        // the whole task
  uint64_t trace_ticks = 0;  // inside bricks
  uint64_t invalid = 0;
  uint64_t hit = 0;
};

// Groups the chunk's `active` rays by their brick (a counting sort, stable,
// so each group keeps input order) into local.grouped; local.touched lists
// the bricks and local.group_end[brick] ends each group.
inline void group_by_brick(SweepScratch& local, std::size_t active, std::size_t base) {
  local.touched.clear();
  for (std::size_t j = 0; j < active; ++j) {
    const uint32_t brick = local.at[local.active[j]];
    if (local.group_end[brick]++ == 0) local.touched.push_back(brick);
  }
  uint32_t offset = 0;
  for (const uint32_t brick : local.touched) {
    const uint32_t count = local.group_end[brick];
    local.group_end[brick] = offset;
    offset += count;
  }
  for (std::size_t j = 0; j < active; ++j) {
    const uint32_t k = local.active[j];
    local.grouped[local.group_end[local.at[k]]++] = static_cast<uint32_t>(base + k);
  }
}

// One round: each group is traced at its brick and each of its rays moves
// on; returns how many rays are still active.
template <QueryKind kKind>
std::size_t sweep_round(const RayWalk<kKind>& walk, SweepPins& pins, SweepScratch& local, std::size_t base,
                        SweepTask& task) {
  std::size_t active = 0;
  uint32_t begin = 0;
  for (const uint32_t brick : local.touched) {
    const uint32_t end = local.group_end[brick];
    local.group_end[brick] = 0;
    const std::span<const uint32_t> ids(local.grouped.data() + begin, end - begin);
    begin = end;
    const BrickAccel* accel = pins.accel(brick);
    if (accel == nullptr) continue;  // the batch fails: the error is returned
    const uint64_t trace_start = ticks();
    task.counters.visits_without_hit += walk.batch.trace(*accel, ids);
    task.trace_ticks += ticks() - trace_start;
    task.visits += ids.size();
    pins.note_rays(brick, ids.size());
    for (const uint32_t ray : ids) {
      const uint32_t k = ray - static_cast<uint32_t>(base);
      const uint32_t next = walk.advance(local.progress[k], ray, task.counters);
      if (next == kInvalidId) continue;
      local.at[k] = next;
      local.active[active++] = k;
    }
  }
  return active;
}

// Chunk c of the batch, swept through all its bricks.
template <QueryKind kKind>
void sweep_chunk(const RayWalk<kKind>& walk, SweepPins& pins, SweepScratch& local, uint32_t brick_count,
                 std::size_t c, SweepTask& task) {
  const QueryBatch<kKind>& batch = walk.batch;
  const uint64_t task_start = ticks();
  if (local.group_end.size() < brick_count) local.group_end.assign(brick_count, 0);
  const std::size_t base = c * kSweepRays;
  const std::size_t size = std::min(batch.size() - base, kSweepRays);
  std::size_t active = 0;
  for (std::size_t k = 0; k < size; ++k) {
    if (!batch.chunk_ray_valid(base + k, task.invalid)) continue;
    const uint32_t brick = walk.start(local.progress[k], base + k, task.counters);
    if (brick == kInvalidId) continue;
    local.at[k] = brick;
    local.active[active++] = static_cast<uint32_t>(k);
  }
  while (active > 0 && !pins.failed()) {
    group_by_brick(local, active, base);
    active = sweep_round(walk, pins, local, base, task);
  }
  for (std::size_t i = base; i < base + size; ++i) task.hit += batch.answered_hit(i);
  task.ticks = ticks() - task_start;
}

}  // namespace

template <QueryKind kKind>
Status run_in_cache_sweep(StrategyContext<kKind>& ctx, std::vector<PinnedBrick> pinned) {
  const uint32_t brick_count = ctx.brick_count();
  QueryStats& stats = ctx.tally.stats;
  SweepPins pins(ctx.cache, ctx.tally, brick_count, std::move(pinned));
  const std::size_t chunks = (ctx.batch.size() + kSweepRays - 1) / kSweepRays;
  std::vector<SweepTask> tasks(chunks);
  const auto t_sweep = Clock::now();
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    sweep_chunk(ctx.walk, pins, ctx.scratch.sweep.local(), brick_count, c, tasks[c]);
  });
  OUTCORE_RETURN_IF_ERROR(pins.status());
  pins.report_rays();
  uint64_t task_ticks = 0, trace_ticks = 0;
  for (const SweepTask& task : tasks) {
    ctx.tally.add(task.counters);
    stats.brick_visits += task.visits;
    if (!ctx.batch.validated_apart) stats.invalid_rays += task.invalid;
    stats.rays_hit += task.hit;
    task_ticks += task.ticks;
    trace_ticks += task.trace_ticks;
  }
  // Upper traversal and tracing interleave: the wall time is split in the
  // proportion of the tasks' own times.
  const double wall = seconds_since(t_sweep) - stats.seconds_build;
  const double brick_share = task_ticks > 0 ? static_cast<double>(trace_ticks) / task_ticks : 0;
  stats.seconds_brick += std::max(0.0, wall) * brick_share;
  stats.seconds_upper += std::max(0.0, wall) * (1 - brick_share);
  return Status::Ok();
}

template Status run_in_cache_sweep(StrategyContext<QueryKind::kClosestHit>&, std::vector<PinnedBrick>);
template Status run_in_cache_sweep(StrategyContext<QueryKind::kAnyHit>&, std::vector<PinnedBrick>);
template Status run_in_cache_sweep(StrategyContext<QueryKind::kAllHits>&, std::vector<PinnedBrick>);

}  // namespace outcore
