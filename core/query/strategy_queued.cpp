// The queued strategy (the default when the scene is not wholly resident):
// the rays of a batch queue at bricks and bricks are processed a wave at a
// time — every waiting brick that is resident now, else a few built at once
// (the longest queues) — each ray advancing brick by brick in its own
// front-to-back order (ray_walk.h). Under a budget smaller than the scene a
// brick being built is also traced by the rays that reach it later
// (trace_ahead.h).
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <optional>
#include <vector>

#include "core/query/brick_queues.h"
#include "core/query/brick_visit.h"
#include "core/query/queued_first_pass.h"
#include "core/query/strategy.h"
#include "core/query/trace_ahead.h"
#include "core/util/cancellation.h"

namespace outcore {
namespace {

// When nothing waiting is resident, up to this many bricks per thread are
// loaded or built and traced in one parallel loop (fewer when the budget
// holds few bricks: a brick built early in the loop must still be resident
// when the loop ends and the rays it passed on come back to the scheduler).
// Cheap loads (the subtree tier) otherwise spend most of a loop on starting
// it and rescanning the waiting bricks (docs/BENCHMARKS.md, "Subtree tier").
constexpr std::size_t kBuildsPerThread = 16;
// ... and at most the budget's bricks over this.
constexpr uint64_t kBudgetBricksPerLoop = 8;

// Bricks per build loop: at least one per thread.
std::size_t bricks_per_build_loop(uint64_t bricks_budget_holds) {
  const std::size_t build_slots = static_cast<std::size_t>(
      std::max(1, std::min<int>(tbb::this_task_arena::max_concurrency(),
                                static_cast<int>(tbb::global_control::active_value(
                                    tbb::global_control::max_allowed_parallelism)))));
  return static_cast<std::size_t>(std::max<uint64_t>(
      build_slots,
      std::min<uint64_t>(build_slots * kBuildsPerThread, bricks_budget_holds / kBudgetBricksPerLoop)));
}

// One task of a wave: a chunk of one resident brick's queue.
struct WaveTask : PinningTask {
  uint32_t brick = 0;
  uint32_t queue = 0;  // index into wave_batches
  std::size_t begin = 0, end = 0;
};

// One brick built (loaded) and traced in a build loop.
struct BuildTask : PinningTask {
  double seconds = 0;  // the whole task
};

template <QueryKind kKind>
class QueuedRun {
 public:
  explicit QueuedRun(StrategyContext<kKind>& ctx)
      : ctx_(ctx),
        queues_(ctx.scratch, ctx.brick_count(), ctx.walk.ahead_state != nullptr),
        ahead_(ctx.walk, ctx.scratch, queues_),
        wave_batches_(ctx.scratch.wave_batches),
        loop_bricks_(bricks_per_build_loop(ctx.bricks_budget_holds)) {}

  Status run() {
    queue_first_bricks(ctx_, queues_);
    std::vector<uint32_t>& waiting = queues_.waiting();
    while (!waiting.empty()) {
      if (cancel_requested()) return batch_interrupted();
      resident_now_.clear();
      not_resident_.clear();
      for (const uint32_t b : waiting)
        (ctx_.cache.is_resident(b) ? resident_now_ : not_resident_).push_back(b);
      if (!resident_now_.empty()) {
        OUTCORE_RETURN_IF_ERROR(trace_resident_wave());
        continue;
      }
      take_longest_queues();
      if (ctx_.gate.defers_to_builds()) {
        pass_over_unhittable();
        if (building_.empty()) continue;
      }
      refresh_residency_and_hint();
      const bool ahead_now = builds_may_evict(building_reserve());
      if (building_.size() == 1) {
        OUTCORE_RETURN_IF_ERROR(build_one(ahead_now));
      } else {
        OUTCORE_RETURN_IF_ERROR(build_several(ahead_now));
      }
    }
    return Status::Ok();
  }

 private:
  bool ahead_possible() const { return ctx_.walk.ahead_state != nullptr; }
  // The batch's rays that have `brick` ahead (0 when not counted): what a
  // builder choosing per brick expects of it beyond its queue.
  uint64_t rays_ahead(uint32_t brick) const { return ctx_.demand.tracking() ? ctx_.demand.of(brick) : 0; }
  RayProgress* progress() const { return ctx_.scratch.progress.data(); }

  void enqueue_moved(const MovedRays& moved) {
    for (const auto& [next, ray] : moved) queues_.enqueue(next, ray);
  }

  // Takes queue b (traced now) into wave_batches_[q].
  void take_queue(uint32_t b, std::size_t q) {
    queues_.take(b, wave_batches_[q]);
    ctx_.tally.stats.brick_visits += wave_batches_[q].size();
  }

  Status trace_resident_wave();
  Status trace_ahead_at_resident();
  void take_longest_queues();
  void pass_over_unhittable();
  uint64_t building_reserve() const;
  void refresh_residency_and_hint();
  bool builds_may_evict(uint64_t building_reserve) const;
  Status build_one(bool ahead_now);
  Status build_several(bool ahead_now);

  StrategyContext<kKind>& ctx_;
  BrickQueues queues_;
  TraceAhead<kKind> ahead_;
  std::vector<std::vector<uint32_t>>& wave_batches_;
  const std::size_t loop_bricks_;
  std::vector<MovedRays> moved_;  // per task: (next brick, ray)
  std::vector<WaveTask> tasks_;
  std::vector<uint32_t> resident_now_, not_resident_;
  std::vector<uint32_t> schedule_hint_;
  std::vector<uint32_t> building_;
  std::vector<BuildTask> build_tasks_;
  std::vector<std::size_t> ahead_begin_;
  std::vector<VisitCounters> chunk_counters_;
  std::vector<uint8_t> passed_over_;  // per brick of building_: no queued ray may hit it
};

// Wave: every waiting brick that is resident now is traced at once, in
// parallel over (brick, chunk) tasks — no build to wait for, and with many
// bricks and short queues (a large scene) parallelism across bricks is what
// keeps the cores busy. Each task pins its brick only while it traces one
// chunk, never waits on the cache while pinned, and runs no nested parallel
// loop, so tasks cannot deadlock on pins.
template <QueryKind kKind>
Status QueuedRun<kKind>::trace_resident_wave() {
  const auto t_brick = Clock::now();
  std::sort(resident_now_.begin(), resident_now_.end());  // a reproducible task order
  tasks_.clear();
  if (wave_batches_.size() < resident_now_.size()) wave_batches_.resize(resident_now_.size());
  for (std::size_t q = 0; q < resident_now_.size(); ++q) {
    const uint32_t b = resident_now_[q];
    ctx_.gate.set_known_resident(b);
    take_queue(b, q);
    for (std::size_t begin = 0; begin < wave_batches_[q].size(); begin += kRayGrain) {
      WaveTask task;
      task.brick = b;
      task.queue = static_cast<uint32_t>(q);
      task.begin = begin;
      task.end = std::min(wave_batches_[q].size(), begin + kRayGrain);
      tasks_.push_back(std::move(task));
    }
  }
  queues_.waiting().swap(not_resident_);
  moved_.resize(std::max(moved_.size(), tasks_.size()));
  tbb::parallel_for(std::size_t{0}, tasks_.size(), [&](std::size_t t) {
    WaveTask& task = tasks_[t];
    moved_[t].clear();
    const std::optional<PinnedBrick> pin =
        pin_for(ctx_.cache, task.brick, task.end - task.begin, task, rays_ahead(task.brick));
    if (!pin) return;
    const std::vector<uint32_t>& batch = wave_batches_[task.queue];
    const std::span<const uint32_t> ids(batch.data() + task.begin, task.end - task.begin);
    trace_and_advance(ctx_.walk, progress(), task.brick, pin->accel(), ids, task.counters, moved_[t]);
  });
  for (std::size_t t = 0; t < tasks_.size(); ++t) {
    const WaveTask& task = tasks_[t];
    OUTCORE_RETURN_IF_ERROR(task.status);
    merge_task(task, ctx_.tally);
    ctx_.tally.stats.seconds_build += task.build_seconds;
    enqueue_moved(moved_[t]);
  }
  OUTCORE_RETURN_IF_ERROR(trace_ahead_at_resident());
  ctx_.tally.stats.seconds_brick += seconds_since(t_brick);
  return Status::Ok();
}

// Once the cache has had to evict, a resident brick may be gone when the
// rays with it further on get there: they are traced now.
template <QueryKind kKind>
Status QueuedRun<kKind>::trace_ahead_at_resident() {
  if (!ahead_possible() || ctx_.cache.counters().evictions <= ctx_.counters_before.evictions)
    return Status::Ok();
  for (const uint32_t b : resident_now_) {
    // One a concurrent batch has evicted since is not rebuilt for this: its
    // listed rays stay listed for when it is built again.
    if (queues_.upcoming(b).empty() || !ctx_.cache.is_resident(b)) continue;
    PinnedBrick pin;
    OUTCORE_RETURN_IF_ERROR(acquire_brick(ctx_.cache, b, queues_.upcoming(b).size(), pin, ctx_.tally));
    ahead_.trace_at(b, pin.accel(), ctx_.tally);
  }
  return Status::Ok();
}

// Nothing waiting is resident: the bricks with the longest queues are to be
// built, at least as many as there are threads (a brick's load and build are
// mostly serial, so one build at a time would leave cores idle) and up to
// kBuildsPerThread each. Takes their queues.
template <QueryKind kKind>
void QueuedRun<kKind>::take_longest_queues() {
  std::vector<uint32_t>& waiting = queues_.waiting();
  const std::size_t want = std::min<std::size_t>(loop_bricks_, waiting.size());
  const auto wanted_end = waiting.begin() + static_cast<std::ptrdiff_t>(want);
  std::partial_sort(waiting.begin(), wanted_end, waiting.end(), [&](uint32_t a, uint32_t b) {
    const std::size_t qa = queues_.queue_size(a), qb = queues_.queue_size(b);
    return qa != qb ? qa > qb : a < b;
  });
  building_.assign(waiting.begin(), wanted_end);
  waiting.erase(waiting.begin(), wanted_end);
  if (wave_batches_.size() < want) wave_batches_.resize(want);
  for (std::size_t q = 0; q < want; ++q) take_queue(building_[q], q);
}

// The reservations of the bricks about to be built.
template <QueryKind kKind>
uint64_t QueuedRun<kKind>::building_reserve() const {
  uint64_t reserve = 0;
  for (const uint32_t b : building_)
    reserve += ctx_.cache.builder().reserve_bytes(ctx_.store.manifest().bricks[b].triangle_count);
  return reserve;
}

// Proxy tests deferred to builds (ProxyGate::defer_to_builds): of the
// bricks about to be built, one whose queued rays none may hit is not built;
// its rays pass over it. Tested in parallel, brick by brick, each queue up
// to its first ray that may hit.
template <QueryKind kKind>
void QueuedRun<kKind>::pass_over_unhittable() {
  const std::size_t count = building_.size();
  passed_over_.assign(count, 0);
  chunk_counters_.assign(count, VisitCounters{});
  moved_.resize(std::max(moved_.size(), count));
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t q) {
    const uint32_t brick = building_[q];
    const std::vector<uint32_t>& rays = wave_batches_[q];
    VisitCounters& counters = chunk_counters_[q];
    moved_[q].clear();
    for (const uint32_t i : rays) {
      if (ctx_.gate.may_hit(brick, ctx_.batch.rays[i], ctx_.batch.horizon(i), counters)) return;
    }
    passed_over_[q] = 1;
    counters.skipped += rays.size();
    advance_past(ctx_.walk, progress(), brick, rays, counters, moved_[q]);
  });
  std::size_t kept = 0;
  for (std::size_t q = 0; q < count; ++q) {
    ctx_.tally.add(chunk_counters_[q]);
    const uint32_t brick = building_[q];
    if (passed_over_[q] == 0) {
      if (kept != q) {
        building_[kept] = brick;
        wave_batches_[kept].swap(wave_batches_[q]);
      }
      ++kept;
      continue;
    }
    ctx_.tally.stats.brick_visits -= wave_batches_[q].size();  // counted when taken, not traced
    enqueue_moved(moved_[q]);
  }
  building_.resize(kept);
}

// One look at what is resident serves both the proxies' view and the
// schedule hint.
template <QueryKind kKind>
void QueuedRun<kKind>::refresh_residency_and_hint() {
  if (!ctx_.gate.tracks_residency() && !ctx_.demand.tracking()) return;
  const std::vector<uint32_t> resident = ctx_.cache.resident_bricks();
  if (ctx_.gate.tracks_residency()) ctx_.gate.mark_known_resident(resident);
  if (!ctx_.demand.tracking() || !ctx_.cache.wants_schedule_hint()) return;
  // Belady on the known part of the schedule: resident bricks ranked by how
  // many rays still need them (most first); those no ray needs are left out,
  // and the policy evicts them first.
  const BrickDemand& demand = ctx_.demand;
  schedule_hint_.clear();
  for (const uint32_t b : resident) {
    if (demand.of(b) > 0) schedule_hint_.push_back(b);
  }
  std::sort(schedule_hint_.begin(), schedule_hint_.end(), [&](uint32_t a, uint32_t b) {
    const uint32_t da = demand.of(a), db = demand.of(b);
    return da != db ? da > db : a < b;
  });
  ctx_.cache.hint_schedule(schedule_hint_);
}

// Builds that may evict: the cache is full or has evicted during this batch.
template <QueryKind kKind>
bool QueuedRun<kKind>::builds_may_evict(uint64_t building_reserve) const {
  if (!ahead_possible()) return false;
  const CacheCounters now = ctx_.cache.counters();
  return now.evictions > ctx_.counters_before.evictions ||
         now.resident_bytes + building_reserve > ctx_.cache.budget_bytes();
}

// One brick: its rays are traced in parallel chunks.
template <QueryKind kKind>
Status QueuedRun<kKind>::build_one(bool ahead_now) {
  const auto t_brick = Clock::now();
  const uint32_t brick = building_[0];
  const std::vector<uint32_t>& batch = wave_batches_[0];
  PinnedBrick pin;
  const uint64_t ahead_rays = ahead_now ? queues_.upcoming(brick).size() : 0;
  OUTCORE_RETURN_IF_ERROR(
      acquire_brick(ctx_.cache, brick, batch.size() + ahead_rays, pin, ctx_.tally, rays_ahead(brick)));
  ctx_.gate.set_known_resident(brick);
  const BrickAccel& accel = pin.accel();
  const std::size_t chunks = (batch.size() + kRayGrain - 1) / kRayGrain;
  moved_.resize(std::max(moved_.size(), chunks));
  chunk_counters_.assign(chunks, VisitCounters{});
  // Isolated: a thread waiting here while the brick is pinned must not pick
  // up another batch's task that could wait on the cache.
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      const std::size_t begin = c * kRayGrain, end = std::min(batch.size(), begin + kRayGrain);
      const std::span<const uint32_t> ids(batch.data() + begin, end - begin);
      moved_[c].clear();
      VisitCounters counters;
      trace_and_advance(ctx_.walk, progress(), brick, accel, ids, counters, moved_[c]);
      chunk_counters_[c] = counters;
    });
  });
  for (std::size_t c = 0; c < chunks; ++c) {
    ctx_.tally.add(chunk_counters_[c]);
    enqueue_moved(moved_[c]);
  }
  if (ahead_now) ahead_.trace_at(brick, accel, ctx_.tally);
  pin.release();
  ctx_.tally.stats.seconds_brick += seconds_since(t_brick);
  return Status::Ok();
}

// Several bricks: one task each loads, builds and pins its brick, traces its
// queue and its trace-ahead candidates (chosen here, among rays not queued at
// any of these bricks, so that no two tasks touch one ray), and unpins. Like
// a wave task it never waits while pinned.
template <QueryKind kKind>
Status QueuedRun<kKind>::build_several(bool ahead_now) {
  const auto t_brick = Clock::now();
  const std::size_t want = building_.size();
  ahead_begin_.assign(want + 1, 0);
  if (ahead_now) {
    for (std::size_t q = 0; q < want; ++q) {
      ahead_begin_[q] = ahead_.selected();
      ahead_.select(building_[q], building_);
    }
  }
  ahead_begin_[want] = ahead_.selected();
  ahead_.reserve(ahead_.selected());
  ahead_.task_counters().assign(want, VisitCounters{});
  build_tasks_.assign(want, BuildTask{});
  moved_.resize(std::max(moved_.size(), want));
  tbb::parallel_for(std::size_t{0}, want, [&](std::size_t q) {
    BuildTask& task = build_tasks_[q];
    moved_[q].clear();
    const uint32_t brick = building_[q];
    const auto t0 = Clock::now();
    const std::size_t rays = wave_batches_[q].size() + (ahead_begin_[q + 1] - ahead_begin_[q]);
    const std::optional<PinnedBrick> pin = pin_for(ctx_.cache, brick, rays, task, rays_ahead(brick));
    if (!pin) return;
    trace_and_advance(ctx_.walk, progress(), brick, pin->accel(), wave_batches_[q], task.counters, moved_[q]);
    ahead_.trace_range(brick, pin->accel(), ahead_begin_[q], ahead_begin_[q + 1], ahead_.task_counters()[q]);
    task.seconds = seconds_since(t0);
  });
  double task_build_seconds = 0, task_seconds = 0;
  for (std::size_t q = 0; q < want; ++q) {
    const BuildTask& task = build_tasks_[q];
    OUTCORE_RETURN_IF_ERROR(task.status);
    ctx_.gate.set_known_resident(building_[q]);
    merge_task(task, ctx_.tally);
    task_build_seconds += task.build_seconds;
    task_seconds += task.seconds;
    enqueue_moved(moved_[q]);
  }
  ahead_.file(ctx_.tally);
  // The tasks overlapped: their wall time is split between building and
  // tracing in the proportion of their own times.
  const double wall = seconds_since(t_brick);
  const double building_share = task_seconds > 0 ? task_build_seconds / task_seconds : 0;
  ctx_.tally.stats.seconds_build += wall * building_share;
  ctx_.tally.stats.seconds_brick += wall * (1 - building_share);
  return Status::Ok();
}

}  // namespace

template <QueryKind kKind>
Status run_queued(StrategyContext<kKind>& ctx) {
  QueuedRun<kKind> queued(ctx);
  return queued.run();
}

template Status run_queued(StrategyContext<QueryKind::kClosestHit>&);
template Status run_queued(StrategyContext<QueryKind::kAnyHit>&);
template Status run_queued(StrategyContext<QueryKind::kAllHits>&);

}  // namespace outcore
