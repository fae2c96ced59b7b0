#include "core/query/query_engine.h"

#include <tbb/parallel_for.h>
#if defined(__x86_64__) || defined(__i386__)
#include <x86intrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

#include "core/upper/upper_traversal.h"
#include "core/util/json_writer.h"

namespace outcore {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// A cheap timestamp for timing short calls (proxy tests, about 100 ns each):
// the time-stamp counter where there is one, converted to seconds against the
// steady clock over the whole query.
inline uint64_t ticks() {
#if defined(__x86_64__) || defined(__i386__)
  return __rdtsc();
#else
  return static_cast<uint64_t>(Clock::now().time_since_epoch().count());
#endif
}

// What advancing rays counts, per task (merged in task order).
struct AdvanceCounters {
  uint64_t nodes = 0;
  uint64_t proxy_tests = 0;
  uint64_t skipped = 0;
  uint64_t proxy_ticks = 0;

  void add_to(QueryStats& stats) const {
    stats.upper_nodes_visited += nodes;
    stats.proxy_tests += proxy_tests;
    stats.bricks_skipped_by_proxy += skipped;
  }
};

// Upcoming bricks kept per ray; more are found by re-traversal when used up.
constexpr std::size_t kWindow = 4;
// Rays per task when tracing inside a brick.
constexpr std::size_t kRayGrain = 512;
// Rays per task when validating a batch.
constexpr std::size_t kCheckGrain = 16384;

struct RayProgress {
  std::array<BrickKey, kWindow> window;
  BrickKey last;  // the key of the brick being (or last) traced
  uint8_t count = 0;
  uint8_t next = 0;
  // The last fill found fewer than kWindow bricks: the window holds every
  // brick left (horizons only shrink), so no refill is needed.
  bool complete = false;
};

// Batches up to this many rays give their scratch back for reuse (about 50
// bytes per ray); larger ones free it, so one huge batch does not pin its
// memory for good.
constexpr std::size_t kKeptScratchRays = std::size_t{1} << 21;
// Scratches kept for reuse (one per concurrent batch).
constexpr std::size_t kKeptScratches = 2;

}  // namespace

// Sized to the batch on entry and overwritten in the first parallel passes;
// the brick queues keep their capacity (a traced queue swaps buffers with the
// wave's batch instead of freeing it).
struct QueryEngine::Scratch {
  std::vector<uint8_t> valid;
  std::vector<RayProgress> progress;
  std::vector<uint32_t> first;
  std::vector<std::vector<uint32_t>> queues;
  std::vector<std::vector<uint32_t>> wave_batches;
};

QueryEngine::QueryEngine(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickCache> cache,
                         std::unique_ptr<const ProxySet> proxies, ProxyOpenReport proxy_report)
    : store_(std::move(store)),
      cache_(std::move(cache)),
      proxies_(std::move(proxies)),
      proxy_report_(std::move(proxy_report)) {}

QueryEngine::~QueryEngine() = default;

std::unique_ptr<QueryEngine::Scratch> QueryEngine::take_scratch() {
  {
    std::lock_guard<std::mutex> lock(scratch_mutex_);
    if (!free_scratch_.empty()) {
      std::unique_ptr<Scratch> scratch = std::move(free_scratch_.back());
      free_scratch_.pop_back();
      return scratch;
    }
  }
  return std::make_unique<Scratch>();
}

void QueryEngine::give_back_scratch(std::unique_ptr<Scratch> scratch) {
  if (scratch->progress.size() > kKeptScratchRays) return;
  std::lock_guard<std::mutex> lock(scratch_mutex_);
  if (free_scratch_.size() < kKeptScratches) free_scratch_.push_back(std::move(scratch));
}

const char* ray_problem(const Ray& ray) {
  if (!is_finite(ray.origin)) return "origin is NaN or infinite";
  if (!is_finite(ray.direction)) return "direction is NaN or infinite";
  if (ray.direction == Vec3f(0, 0, 0)) return "direction is zero";
  if (!std::isfinite(ray.tnear) || ray.tnear < 0.0f) return "tnear is negative, NaN or infinite";
  if (std::isnan(ray.tfar)) return "tfar is NaN";
  if (ray.tnear > ray.tfar) return "tnear > tfar";
  return nullptr;
}

Expected<std::unique_ptr<QueryEngine>> QueryEngine::open(const std::string& store_directory,
                                                         const EngineOptions& options) {
  OUTCORE_ASSIGN_OR_RETURN(auto store, SceneStore::open(store_directory));
  return create(std::move(store), options);
}

Expected<std::unique_ptr<QueryEngine>> QueryEngine::create(std::shared_ptr<const SceneStore> store,
                                                           const EngineOptions& options) {
  if (options.cache_bytes == 0) return invalid_argument("the cache budget must be positive");
  OUTCORE_ASSIGN_OR_RETURN(auto builder, make_brick_builder(options.brick_accel, options.accel_options));
  OUTCORE_ASSIGN_OR_RETURN(auto policy, make_eviction_policy(options.eviction_policy));
  std::unique_ptr<const ProxySet> proxies;
  ProxyOpenReport proxy_report;
  if (options.proxies) {
    OUTCORE_ASSIGN_OR_RETURN(proxies, ProxySet::open(*store, options.proxy_config, &proxy_report));
  }
  auto cache =
      std::make_unique<BrickCache>(store, std::move(builder), std::move(policy), options.cache_bytes);
  if (options.access_trace) cache->set_access_trace(options.access_trace);
  if (!options.subtree_dir.empty())
    OUTCORE_RETURN_IF_ERROR(cache->enable_subtree_tier({options.subtree_dir, options.subtree_max_bytes}));
  return std::unique_ptr<QueryEngine>(
      new QueryEngine(std::move(store), std::move(cache), std::move(proxies), std::move(proxy_report)));
}

Status QueryEngine::intersect(std::span<const Ray> rays, std::span<Hit> hits, const QueryOptions& options,
                              QueryStats* stats) {
  if (hits.size() != rays.size()) return invalid_argument("hits and rays differ in length");
  return run<QueryKind::kClosestHit>(rays, hits.data(), nullptr, options, stats);
}

Status QueryEngine::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded,
                             const QueryOptions& options, QueryStats* stats) {
  if (occluded.size() != rays.size()) return invalid_argument("occlusion flags and rays differ in length");
  return run<QueryKind::kAnyHit>(rays, nullptr, occluded.data(), options, stats);
}

template <QueryKind kKind>
Status QueryEngine::run(std::span<const Ray> rays, Hit* hits, uint8_t* occluded, const QueryOptions& options,
                        QueryStats* stats_out) {
  const auto start = Clock::now();
  const uint64_t ticks_start = ticks();
  uint64_t proxy_ticks = 0;
  const ProxySet* const proxies = proxies_.get();
  // This batch's view of which bricks are resident. A proxy saves a load and
  // a build, never tracing time (testing one costs about as much as tracing a
  // small brick), so it is consulted only for bricks not known to be
  // resident: a fully cached scene pays nothing for proxies. Skipping or not
  // never changes an answer, so a stale view costs at most a load or a test.
  // Written only between parallel phases.
  std::vector<uint8_t> known_resident;
  const auto mark_known_resident = [&](const std::vector<uint32_t>& resident) {
    std::fill(known_resident.begin(), known_resident.end(), uint8_t{0});
    for (const uint32_t b : resident) known_resident[b] = 1;
  };
  if (proxies != nullptr && options.reorder) {
    known_resident.assign(store_->brick_count(), 0);
    mark_known_resident(cache_->resident_bricks());
  }
  const CacheCounters counters_before = cache_->counters();
  const UpperHierarchy& upper = store_->manifest().upper;
  const std::size_t n = rays.size();
  QueryStats stats;
  stats.rays = n;

  std::unique_ptr<Scratch> scratch = take_scratch();
  struct GiveBack {
    QueryEngine* engine;
    std::unique_ptr<Scratch>& scratch;
    ~GiveBack() { engine->give_back_scratch(std::move(scratch)); }
  } give_back{this, scratch};
  // Grown only (new elements are value-initialised once); every element
  // below n is overwritten below, in parallel.
  if (scratch->valid.size() < n) scratch->valid.resize(n);
  if (scratch->progress.size() < n) scratch->progress.resize(n);
  std::vector<uint8_t>& valid = scratch->valid;
  std::vector<RayProgress>& progress = scratch->progress;
  // A hierarchy of a few bricks is traversed flat (all leaf boxes tested at
  // once), a larger one 4-wide: same bricks, same keys, fewer branches
  // (upper_traversal.h).
  FlatLeaves flat;
  const bool use_flat = make_flat_leaves(upper, flat);
  WideUpper wide;
  if (!use_flat) make_wide_upper(upper, wide);

  // Validation and reset of the outputs and per-ray progress, in parallel
  // chunks; the first bad ray of each chunk is kept so that strict mode names
  // the first of the batch.
  const std::size_t check_chunks = (n + kCheckGrain - 1) / kCheckGrain;
  std::vector<uint64_t> chunk_invalid(check_chunks, 0);
  std::vector<std::size_t> chunk_first_bad(check_chunks, n);
  tbb::parallel_for(std::size_t{0}, check_chunks, [&](std::size_t c) {
    const std::size_t end = std::min(n, (c + 1) * kCheckGrain);
    for (std::size_t i = c * kCheckGrain; i < end; ++i) {
      const bool ok = ray_problem(rays[i]) == nullptr;
      valid[i] = ok;
      progress[i] = RayProgress{};
      if (!ok) {
        if (chunk_first_bad[c] == n) chunk_first_bad[c] = i;
        ++chunk_invalid[c];
      }
      if constexpr (kKind == QueryKind::kClosestHit) {
        hits[i] = Hit{};
      } else {
        occluded[i] = 0;
      }
    }
  });
  for (std::size_t c = 0; c < check_chunks; ++c) {
    if (chunk_first_bad[c] != n && options.strict) {
      const std::size_t i = chunk_first_bad[c];
      return invalid_argument("ray " + std::to_string(i) + ": " + ray_problem(rays[i]));
    }
    stats.invalid_rays += chunk_invalid[c];
  }

  // The largest distance at which a brick can still matter for ray i.
  auto horizon = [&](std::size_t i) {
    if constexpr (kKind == QueryKind::kClosestHit) return std::min(rays[i].tfar, hits[i].t);
    return rays[i].tfar;
  };
  auto finished = [&](std::size_t i) {
    if constexpr (kKind == QueryKind::kAnyHit) return occluded[i] != 0;
    return false;
  };
  auto trace = [&](const BrickAccel& accel, std::span<const uint32_t> ids) {
    if constexpr (kKind == QueryKind::kClosestHit) {
      accel.intersect(ids, rays.data(), hits);
    } else {
      accel.occluded(ids, rays.data(), occluded);
    }
  };
  // Demand per brick, for a schedule-aware policy (SchedulePolicy): how many
  // rays still have the brick ahead of them, in their window of upcoming
  // bricks or in its queue. Counted only when the policy uses hints; one
  // relaxed atomic per window entry and one per traced chunk.
  const bool track_demand = options.reorder && cache_->wants_schedule_hint();
  std::vector<std::atomic<uint32_t>> demand(track_demand ? store_->brick_count() : 0);
  auto drop_window = [&](RayProgress& p) {
    if (!track_demand) return;
    for (; p.next < p.count; ++p.next) demand[p.window[p.next].brick].fetch_sub(1, std::memory_order_relaxed);
  };
  // Moves ray i past its current brick; returns the next brick or kInvalidId.
  // A brick whose proxy the ray's remaining segment cannot hit is passed over
  // like a traced brick without a hit (it has none to give), so the ray's
  // hit, horizon and brick order are what they are with proxies off.
  auto advance = [&](std::size_t i, AdvanceCounters& counters) -> uint32_t {
    RayProgress& p = progress[i];
    if (finished(i)) {
      drop_window(p);
      return kInvalidId;
    }
    const float limit = horizon(i);
    for (;;) {
      BrickKey key;
      if (p.next < p.count) {
        key = p.window[p.next];
        if (key.entry > limit) {
          drop_window(p);
          return kInvalidId;
        }
        p.last = key;
        ++p.next;
      } else {
        if (p.complete) return kInvalidId;
        const SlabRay slab_ray(rays[i]);
        p.count = static_cast<uint8_t>(
            use_flat
                ? next_bricks_flat(flat, slab_ray, rays[i].tnear, limit, p.last, p.window, counters.nodes)
                : next_bricks_wide(wide, slab_ray, rays[i].tnear, limit, p.last, p.window, counters.nodes));
        p.complete = p.count < kWindow;
        p.next = 0;
        if (track_demand) {
          for (uint8_t k = 0; k < p.count; ++k)
            demand[p.window[k].brick].fetch_add(1, std::memory_order_relaxed);
        }
        if (p.count == 0) return kInvalidId;
        key = p.window[0];
        p.last = key;
        p.next = 1;
      }
      if (proxies == nullptr || (!known_resident.empty() && known_resident[key.brick])) return key.brick;
      ++counters.proxy_tests;
      const uint64_t t0 = ticks();
      const bool may_hit = proxies->brick(key.brick).may_hit(rays[i], rays[i].tnear, limit);
      counters.proxy_ticks += ticks() - t0;
      if (may_hit) return key.brick;
      ++counters.skipped;
      // Passed over: the ray no longer needs the brick.
      if (track_demand) demand[key.brick].fetch_sub(1, std::memory_order_relaxed);
    }
  };

  auto acquire = [&](uint32_t brick, PinnedBrick& pin) -> Status {
    const auto t0 = Clock::now();
    auto acquired = cache_->acquire(brick);
    stats.seconds_build += seconds_since(t0);
    if (!acquired.ok()) return acquired.status();
    pin = std::move(acquired).value();
    ++stats.brick_acquisitions;
    ++(pin.was_hit() ? stats.cache_hits : stats.cache_misses);
    return Status::Ok();
  };

  if (!options.reorder) {
    // One ray at a time, in input order, brick by brick.
    for (std::size_t i = 0; i < n; ++i) {
      if (!valid[i]) continue;
      const uint32_t id = static_cast<uint32_t>(i);
      const auto t0 = Clock::now();
      AdvanceCounters counters;
      for (uint32_t brick = advance(i, counters); brick != kInvalidId; brick = advance(i, counters)) {
        PinnedBrick pin;
        OUTCORE_RETURN_IF_ERROR(acquire(brick, pin));
        trace(pin.accel(), std::span<const uint32_t>(&id, 1));
        ++stats.brick_visits;
      }
      counters.add_to(stats);
      proxy_ticks += counters.proxy_ticks;
      stats.seconds_brick += seconds_since(t0);
    }
  } else {
    const uint32_t brick_count = store_->brick_count();
    std::vector<std::vector<uint32_t>>& queues = scratch->queues;
    if (queues.size() < brick_count) queues.resize(brick_count);
    for (auto& queue : queues) queue.clear();  // a failed batch may have left rays
    std::vector<uint32_t> waiting;             // bricks with a non-empty queue
    std::vector<uint8_t> is_waiting(brick_count, 0);
    auto enqueue = [&](uint32_t brick, uint32_t ray) {
      queues[brick].push_back(ray);
      if (!is_waiting[brick]) {
        is_waiting[brick] = 1;
        waiting.push_back(brick);
      }
    };

    // First brick of every ray, in parallel; per-chunk results merged in order.
    const auto t_upper = Clock::now();
    const std::size_t chunks = (n + kRayGrain - 1) / kRayGrain;
    std::vector<AdvanceCounters> chunk_counters(chunks);
    if (scratch->first.size() < n) scratch->first.resize(n);
    std::vector<uint32_t>& first = scratch->first;
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      AdvanceCounters counters;
      for (std::size_t i = c * kRayGrain; i < std::min(n, (c + 1) * kRayGrain); ++i) {
        first[i] = valid[i] ? advance(i, counters) : kInvalidId;
      }
      chunk_counters[c] = counters;
    });
    for (const AdvanceCounters& counters : chunk_counters) {
      counters.add_to(stats);
      proxy_ticks += counters.proxy_ticks;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (first[i] != kInvalidId) enqueue(first[i], static_cast<uint32_t>(i));
    }
    stats.seconds_upper = seconds_since(t_upper);

    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> moved;  // per task: (next brick, ray)
    // One task of a wave: a chunk of one resident brick's queue.
    struct WaveTask {
      uint32_t brick;
      uint32_t queue;  // index into wave_batches
      std::size_t begin, end;
      AdvanceCounters counters;
      double build_seconds = 0;
      bool acquired = false, was_hit = false;
      Status status;
    };
    std::vector<WaveTask> tasks;
    std::vector<std::vector<uint32_t>>& wave_batches = scratch->wave_batches;
    std::vector<uint32_t> resident_now, not_resident;
    std::vector<uint32_t> schedule_hint;
    while (!waiting.empty()) {
      // Wave: every waiting brick that is resident now is traced at once, in
      // parallel over (brick, chunk) tasks — no build to wait for, and with
      // many bricks and short queues (a large scene) parallelism across
      // bricks is what keeps both cores busy. Each task pins its brick only
      // while it traces one chunk, never waits on the cache while pinned, and
      // runs no nested parallel loop, so tasks cannot deadlock on pins.
      resident_now.clear();
      not_resident.clear();
      for (const uint32_t b : waiting) (cache_->is_resident(b) ? resident_now : not_resident).push_back(b);
      if (!resident_now.empty()) {
        const auto t_brick = Clock::now();
        std::sort(resident_now.begin(), resident_now.end());  // a reproducible task order
        tasks.clear();
        if (wave_batches.size() < resident_now.size()) wave_batches.resize(resident_now.size());
        for (std::size_t q = 0; q < resident_now.size(); ++q) {
          const uint32_t b = resident_now[q];
          is_waiting[b] = 0;
          if (!known_resident.empty()) known_resident[b] = 1;
          wave_batches[q].swap(queues[b]);  // both keep their buffers
          queues[b].clear();
          stats.brick_visits += wave_batches[q].size();
          for (std::size_t begin = 0; begin < wave_batches[q].size(); begin += kRayGrain) {
            WaveTask task;
            task.brick = b;
            task.queue = static_cast<uint32_t>(q);
            task.begin = begin;
            task.end = std::min(wave_batches[q].size(), begin + kRayGrain);
            tasks.push_back(std::move(task));
          }
        }
        waiting.swap(not_resident);
        moved.resize(std::max(moved.size(), tasks.size()));
        tbb::parallel_for(std::size_t{0}, tasks.size(), [&](std::size_t t) {
          WaveTask& task = tasks[t];
          moved[t].clear();
          const auto t0 = Clock::now();
          auto acquired = cache_->acquire(task.brick);
          task.build_seconds = seconds_since(t0);
          if (!acquired.ok()) {
            task.status = acquired.status();
            return;
          }
          const PinnedBrick pin = std::move(acquired).value();
          task.acquired = true;
          task.was_hit = pin.was_hit();
          const std::vector<uint32_t>& batch = wave_batches[task.queue];
          const std::span<const uint32_t> ids(batch.data() + task.begin, task.end - task.begin);
          trace(pin.accel(), ids);
          if (track_demand)
            demand[task.brick].fetch_sub(static_cast<uint32_t>(ids.size()), std::memory_order_relaxed);
          for (const uint32_t ray : ids) {
            const uint32_t next = advance(ray, task.counters);
            if (next != kInvalidId) moved[t].emplace_back(next, ray);
          }
        });
        for (std::size_t t = 0; t < tasks.size(); ++t) {
          const WaveTask& task = tasks[t];
          OUTCORE_RETURN_IF_ERROR(task.status);
          task.counters.add_to(stats);
          proxy_ticks += task.counters.proxy_ticks;
          stats.seconds_build += task.build_seconds;
          ++stats.brick_acquisitions;
          ++(task.was_hit ? stats.cache_hits : stats.cache_misses);
          for (const auto& [next, ray] : moved[t]) enqueue(next, ray);
        }
        stats.seconds_brick += seconds_since(t_brick);
        continue;
      }

      // Nothing waiting is resident: build the longest queue's brick, then
      // trace its rays in parallel chunks.
      std::size_t best = 0;
      for (std::size_t k = 1; k < waiting.size(); ++k) {
        if (queues[waiting[k]].size() > queues[waiting[best]].size()) best = k;
      }
      const uint32_t brick = waiting[best];
      waiting[best] = waiting.back();
      waiting.pop_back();
      is_waiting[brick] = 0;
      std::vector<uint32_t> batch = std::move(queues[brick]);
      queues[brick] = {};

      // One look at what is resident serves both the proxies' view and the
      // schedule hint.
      if (!known_resident.empty() || track_demand) {
        const std::vector<uint32_t> resident = cache_->resident_bricks();
        if (!known_resident.empty()) mark_known_resident(resident);
        if (track_demand) {
          // Belady on the known part of the schedule: resident bricks ranked
          // by how many rays still need them (most first); those no ray needs
          // are left out, and the policy evicts them first.
          schedule_hint.clear();
          for (const uint32_t b : resident) {
            if (demand[b].load(std::memory_order_relaxed) > 0) schedule_hint.push_back(b);
          }
          std::sort(schedule_hint.begin(), schedule_hint.end(), [&](uint32_t a, uint32_t b) {
            const uint32_t da = demand[a].load(std::memory_order_relaxed),
                           db = demand[b].load(std::memory_order_relaxed);
            return da != db ? da > db : a < b;
          });
          cache_->hint_schedule(schedule_hint);
        }
      }
      PinnedBrick pin;
      OUTCORE_RETURN_IF_ERROR(acquire(brick, pin));
      if (!known_resident.empty()) known_resident[brick] = 1;
      const auto t_brick = Clock::now();
      const BrickAccel& accel = pin.accel();
      const std::size_t batch_chunks = (batch.size() + kRayGrain - 1) / kRayGrain;
      moved.resize(std::max(moved.size(), batch_chunks));
      chunk_counters.assign(batch_chunks, AdvanceCounters{});
      tbb::parallel_for(std::size_t{0}, batch_chunks, [&](std::size_t c) {
        const std::size_t begin = c * kRayGrain, end = std::min(batch.size(), begin + kRayGrain);
        const std::span<const uint32_t> ids(batch.data() + begin, end - begin);
        moved[c].clear();
        trace(accel, ids);
        if (track_demand)
          demand[brick].fetch_sub(static_cast<uint32_t>(ids.size()), std::memory_order_relaxed);
        AdvanceCounters counters;
        for (const uint32_t ray : ids) {
          const uint32_t next = advance(ray, counters);
          if (next != kInvalidId) moved[c].emplace_back(next, ray);
        }
        chunk_counters[c] = counters;
      });
      pin.release();
      stats.brick_visits += batch.size();
      for (std::size_t c = 0; c < batch_chunks; ++c) {
        chunk_counters[c].add_to(stats);
        proxy_ticks += chunk_counters[c].proxy_ticks;
        for (const auto& [next, ray] : moved[c]) enqueue(next, ray);
      }
      stats.seconds_brick += seconds_since(t_brick);
    }
  }

  std::vector<uint64_t> chunk_hits(check_chunks, 0);  // counted in parallel, summed in order
  tbb::parallel_for(std::size_t{0}, check_chunks, [&](std::size_t c) {
    uint64_t hit = 0;
    for (std::size_t i = c * kCheckGrain; i < std::min(n, (c + 1) * kCheckGrain); ++i) {
      if constexpr (kKind == QueryKind::kClosestHit) {
        hit += hits[i].is_hit();
      } else {
        hit += occluded[i] != 0;
      }
    }
    chunk_hits[c] = hit;
  });
  for (const uint64_t hit : chunk_hits) stats.rays_hit += hit;
  const CacheCounters counters_after = cache_->counters();
  stats.brick_builds = counters_after.builds - counters_before.builds;
  stats.evictions = counters_after.evictions - counters_before.evictions;
  const SubtreeTierCounters& tier_before = counters_before.subtree;
  const SubtreeTierCounters& tier_after = counters_after.subtree;
  stats.subtree_loads = tier_after.loads - tier_before.loads;
  stats.subtree_writes = tier_after.writes - tier_before.writes;
  stats.subtree_rejects = tier_after.rejected() - tier_before.rejected();
  stats.subtree_bytes_read = tier_after.bytes_read - tier_before.bytes_read;
  stats.subtree_bytes_written = tier_after.bytes_written - tier_before.bytes_written;
  stats.seconds_brick_builds = counters_after.build_seconds - counters_before.build_seconds;
  stats.seconds_subtree_loads = tier_after.load_seconds - tier_before.load_seconds;
  stats.peak_bytes_resident = counters_after.peak_resident_bytes;
  stats.cache_budget_bytes = cache_->budget_bytes();
  stats.seconds_total = seconds_since(start);
  if (proxies != nullptr) {
    stats.proxy_bytes = proxies->memory_bytes();
    const uint64_t elapsed_ticks = ticks() - ticks_start;
    if (elapsed_ticks > 0) stats.seconds_proxy = stats.seconds_total * proxy_ticks / elapsed_ticks;
  }
  if (stats_out != nullptr) *stats_out = stats;
  return Status::Ok();
}

std::string QueryStats::to_json() const {
  JsonWriter j;
  j.begin_object();
  j.field("rays", rays).field("invalid_rays", invalid_rays).field("rays_hit", rays_hit);
  j.field("upper_nodes_visited", upper_nodes_visited).field("brick_visits", brick_visits);
  j.field("proxy_tests", proxy_tests).field("bricks_skipped_by_proxy", bricks_skipped_by_proxy);
  j.field("proxy_bytes", proxy_bytes);
  j.field("brick_acquisitions", brick_acquisitions)
      .field("cache_hits", cache_hits)
      .field("cache_misses", cache_misses);
  j.field("brick_builds", brick_builds).field("evictions", evictions);
  j.field("subtree_loads", subtree_loads).field("subtree_writes", subtree_writes);
  j.field("subtree_rejects", subtree_rejects).field("subtree_bytes_read", subtree_bytes_read);
  j.field("subtree_bytes_written", subtree_bytes_written);
  j.field("peak_bytes_resident", peak_bytes_resident).field("cache_budget_bytes", cache_budget_bytes);
  j.key("seconds").begin_object();
  j.field("total", seconds_total).field("upper", seconds_upper).field("build", seconds_build);
  j.field("brick", seconds_brick).field("proxy", seconds_proxy);
  j.field("brick_builds_summed", seconds_brick_builds).field("subtree_loads_summed", seconds_subtree_loads);
  j.end_object();
  j.field("rays_per_second", seconds_total > 0 ? rays / seconds_total : 0.0);
  j.end_object();
  return j.str();
}

std::string QueryStats::to_text() const {
  char buf[1024];
  std::snprintf(
      buf, sizeof buf,
      "rays %llu (%llu hit, %llu invalid) in %.3f s = %.2f M rays/s\n"
      "  upper: %llu nodes visited, %.3f s first pass\n"
      "  bricks: %llu ray visits, %llu acquisitions (%llu hits, %llu misses), %llu builds, %llu "
      "evictions\n"
      "  cache: peak %.1f MiB of %.1f MiB budget\n"
      "  time: build/wait %.3f s, brick traversal %.3f s\n",
      static_cast<unsigned long long>(rays), static_cast<unsigned long long>(rays_hit),
      static_cast<unsigned long long>(invalid_rays), seconds_total,
      seconds_total > 0 ? rays / seconds_total / 1e6 : 0.0,
      static_cast<unsigned long long>(upper_nodes_visited), seconds_upper,
      static_cast<unsigned long long>(brick_visits), static_cast<unsigned long long>(brick_acquisitions),
      static_cast<unsigned long long>(cache_hits), static_cast<unsigned long long>(cache_misses),
      static_cast<unsigned long long>(brick_builds), static_cast<unsigned long long>(evictions),
      peak_bytes_resident / 1048576.0, cache_budget_bytes / 1048576.0, seconds_build, seconds_brick);
  std::string text = buf;
  if (proxy_bytes > 0) {
    const uint64_t candidates = brick_visits + bricks_skipped_by_proxy;
    std::snprintf(buf, sizeof buf,
                  "  proxies: %llu of %llu brick visits skipped (%.1f %%), %llu tests, %.3f s (all threads), "
                  "%.2f MiB resident\n",
                  static_cast<unsigned long long>(bricks_skipped_by_proxy),
                  static_cast<unsigned long long>(candidates),
                  candidates > 0 ? 100.0 * bricks_skipped_by_proxy / candidates : 0.0,
                  static_cast<unsigned long long>(proxy_tests), seconds_proxy, proxy_bytes / 1048576.0);
    text += buf;
  } else {
    text += "  proxies: off\n";
  }
  if (subtree_loads + subtree_writes + subtree_rejects > 0) {
    std::snprintf(buf, sizeof buf,
                  "  subtree tier: %llu loads (%.1f MiB, %.3f s), %llu writes (%.1f MiB), %llu rejected; "
                  "builds %.3f s\n",
                  static_cast<unsigned long long>(subtree_loads), subtree_bytes_read / 1048576.0,
                  seconds_subtree_loads, static_cast<unsigned long long>(subtree_writes),
                  subtree_bytes_written / 1048576.0, static_cast<unsigned long long>(subtree_rejects),
                  seconds_brick_builds);
    text += buf;
  }
  return text;
}

template Status QueryEngine::run<QueryKind::kClosestHit>(std::span<const Ray>, Hit*, uint8_t*,
                                                         const QueryOptions&, QueryStats*);
template Status QueryEngine::run<QueryKind::kAnyHit>(std::span<const Ray>, Hit*, uint8_t*,
                                                     const QueryOptions&, QueryStats*);

}  // namespace outcore
