#include "core/query/query_engine.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#if defined(__x86_64__) || defined(__i386__)
#include <x86intrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <optional>

#include "core/accel/embree_brick_set.h"
#include "core/cache/cache_budget.h"
#include "core/upper/upper_packet_traversal.h"
#include "core/upper/upper_traversal.h"
#include "core/upper/upper_wide8_traversal.h"
#include "core/util/cancellation.h"
#include "core/util/cpu_features.h"

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
  uint64_t ahead_visits = 0;  // visits whose tracing was done ahead of time
  uint64_t ahead_traces = 0;
  uint64_t rays_hit = 0;      // rays finished with a hit (queued path)
  uint64_t invalid_rays = 0;  // found invalid in the queued path's first pass

  void add_to(QueryStats& stats) const {
    stats.rays_hit += rays_hit;
    stats.invalid_rays += invalid_rays;
    stats.upper_nodes_visited += nodes;
    stats.brick_visits += ahead_visits;
    stats.rays_traced_ahead += ahead_traces;
    stats.proxy_tests += proxy_tests;
    stats.bricks_skipped_by_proxy += skipped;
  }
};

// Upcoming bricks kept per ray; more are found by re-traversal when used up.
constexpr std::size_t kWindow = 4;
// Rays per task when tracing inside a brick.
constexpr std::size_t kRayGrain = 512;
// How many rays ahead advance() loops prefetch per-ray state.
constexpr std::size_t kAdvancePrefetch = 8;
// Rays per task when validating a batch.
constexpr std::size_t kCheckGrain = 16384;
// When nothing waiting is resident, up to this many bricks per thread are
// loaded or built and traced in one parallel loop (fewer when the budget
// holds few bricks: a brick built early in the loop must still be resident
// when the loop ends and the rays it passed on come back to the scheduler).
// Cheap loads (the subtree tier: ~0.1 ms against ~0.2 ms of tracing per
// brick) otherwise spend most of a loop on starting it and rescanning the
// waiting bricks (docs/BENCHMARKS.md, "Subtree tier": 100 M triangles at a
// quarter budget, 1.2 s -> 0.95 s a warm batch).
constexpr std::size_t kBuildsPerThread = 16;
// ... and at most the budget's bricks over this.
constexpr uint64_t kBudgetBricksPerLoop = 8;

// What is known of a window entry the ray has not reached yet: nothing, or
// the outcome of tracing it there ahead of its turn (trace-ahead, below);
// values from kAheadHitBase on index the batch's table of such hits.
constexpr uint32_t kAheadNone = 0;
constexpr uint32_t kAheadSkip = 1;    // its proxy says the ray cannot hit it
constexpr uint32_t kAheadNoGain = 2;  // traced: nothing beats what the ray had then
constexpr uint32_t kAheadHitBase = 3;

struct RayProgress {
  std::array<BrickKey, kWindow> window;
  BrickKey last;  // the key of the brick being (or last) traced
  uint8_t count = 0;
  uint8_t next = 0;
  // The last fill found fewer than kWindow bricks: the window holds every
  // brick left (horizons only shrink), so no refill is needed.
  bool complete = false;
  // Window entries already listed at their brick for trace-ahead (bit k).
  uint8_t listed = 0;
};

// Rays per task of the in-cache sweep (below): its per-ray state (about 60
// bytes a ray) and the rays' own records stay in a core's L2 cache.
constexpr std::size_t kSweepRays = 1024;
// The in-cache sweep is used for scenes of at most this many bricks.
constexpr uint32_t kSweepMaxBricks = 16;

// One thread's working memory for the in-cache sweep of one chunk of rays.
struct SweepScratch {
  std::array<RayProgress, kSweepRays> progress;
  std::array<uint32_t, kSweepRays> at;       // the brick each active ray is at
  std::array<uint32_t, kSweepRays> active;   // chunk-local indices of the rays with a brick to trace
  std::array<uint32_t, kSweepRays> grouped;  // the active rays' ids, grouped by brick
  std::vector<uint32_t> group_end;           // per brick; all zero between rounds
  std::vector<uint32_t> touched;             // bricks with active rays, in first-seen order
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
  // Trace-ahead: per brick, rays with it further on in their window; and the
  // hits found ahead of their turn.
  std::vector<std::vector<uint32_t>> upcoming;
  // kAhead* per ray and window entry (apart from RayProgress, which stays
  // small for batches that fit the cache).
  std::vector<std::array<uint32_t, kWindow>> ahead_state;
  std::vector<Hit> ahead_hits;
  std::vector<Ray> ahead_ray_copies;
  std::vector<Hit> ahead_hit_copies;
  std::vector<uint8_t> ahead_occluded;
  std::vector<uint32_t> ahead_outcomes;
  tbb::enumerable_thread_specific<SweepScratch> sweep;
};

struct QueryEngine::UpperWalks {
  // A hierarchy of a few bricks is traversed flat (all leaf boxes tested at
  // once), a larger one 4- or 8-wide: same bricks, same keys, fewer branches
  // (upper_traversal.h).
  FlatLeaves flat;
  bool use_flat = false;
  WideUpper wide;
  WideUpper8 wide8;

  explicit UpperWalks(const UpperHierarchy& upper) {
    use_flat = make_flat_leaves(upper, flat);
    if (use_flat) return;
    make_wide_upper(upper, wide);
    make_wide_upper(upper, wide8);
  }
};

QueryEngine::QueryEngine(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickCache> cache,
                         std::unique_ptr<const ProxySet> proxies, ProxyOpenReport proxy_report,
                         bool cache_fits_scene, uint64_t bricks_budget_holds)
    : store_(std::move(store)),
      cache_(std::move(cache)),
      proxies_(std::move(proxies)),
      proxy_report_(std::move(proxy_report)),
      cache_fits_scene_(cache_fits_scene),
      bricks_budget_holds_(bricks_budget_holds),
      upper_walks_(std::make_unique<const UpperWalks>(store_->manifest().upper)) {}

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

Expected<std::unique_ptr<QueryEngine>> QueryEngine::open(const std::string& store_directory,
                                                         const EngineOptions& options) {
  OUTCORE_ASSIGN_OR_RETURN(auto store, SceneStore::open(store_directory));
  return create(std::move(store), options);
}

Expected<std::unique_ptr<QueryEngine>> QueryEngine::create(std::shared_ptr<const SceneStore> store,
                                                           const EngineOptions& options) {
  if (options.cache_bytes == 0) return invalid_argument("the cache budget must be positive");
  BrickAccelOptions accel_options = options.accel_options;
  OUTCORE_ASSIGN_OR_RETURN(auto builder, make_brick_builder(options.brick_accel, accel_options));
  OUTCORE_ASSIGN_OR_RETURN(auto policy, make_eviction_policy(options.eviction_policy));
  // Before the proxies (which may build and write proxies.bin): a budget no
  // brick-by-brick schedule can work under is the user's error, found now.
  OUTCORE_RETURN_IF_ERROR(check_cache_budget(store->manifest(), *builder, options.cache_bytes));
  std::unique_ptr<const ProxySet> proxies;
  ProxyOpenReport proxy_report;
  if (options.proxies) {
    OUTCORE_ASSIGN_OR_RETURN(proxies, ProxySet::open(*store, options.proxy_config, &proxy_report));
  }
  // Whether the budget holds every brick at once (by the builder's
  // reservations, which bound what a brick holds): then nothing is ever
  // evicted and trace-ahead has nothing to save.
  uint64_t reserved = 0;
  for (const BrickRecord& brick : store->manifest().bricks)
    reserved += builder->reserve_bytes(brick.triangle_count);
  const bool cache_fits_scene = reserved <= options.cache_bytes;
  const uint64_t brick_count = std::max<uint64_t>(1, store->manifest().bricks.size());
  const uint64_t bricks_budget_holds = options.cache_bytes / std::max<uint64_t>(1, reserved / brick_count);
  // The build quality is never changed behind the user's back, although
  // under a tight budget Embree's low quality would build about 3x faster:
  // a ray running in an axis plane (a zero direction component) along a
  // mesh edge in that plane hits one of the edge's two triangles or the
  // other depending on which of Embree's boxes have a face in the plane,
  // i.e. on the tree, so answers would depend on the budget
  // (QueryEngine.ABudgetBelowTheSceneKeepsTheBuildQualityAndEveryAnswer).
  auto cache =
      std::make_unique<BrickCache>(store, std::move(builder), std::move(policy), options.cache_bytes);
  if (options.access_trace) cache->set_access_trace(options.access_trace);
  if (!options.subtree_dir.empty())
    OUTCORE_RETURN_IF_ERROR(cache->enable_subtree_tier(
        {options.subtree_dir, options.subtree_max_bytes, options.subtree_release_batch_bytes}));
  auto engine = std::unique_ptr<QueryEngine>(new QueryEngine(std::move(store), std::move(cache),
                                                             std::move(proxies), std::move(proxy_report),
                                                             cache_fits_scene, bricks_budget_holds));
  engine->accel_options_ = std::move(accel_options);
  engine->embree_bricks_ = options.brick_accel == "embree";
  return engine;
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

namespace {

Status interrupted() {
  return cancelled("the batch was cancelled before all its rays were traced (the process is stopping)");
}

}  // namespace

template <QueryKind kKind>
Status QueryEngine::run(std::span<const Ray> rays, Hit* hits, uint8_t* occluded, const QueryOptions& options,
                        QueryStats* stats_out) {
  const auto start = Clock::now();
  const uint64_t ticks_start = ticks();
  uint64_t proxy_ticks = 0;
  const ProxySet* const proxies = proxies_.get();
  const double hit_rounding = cache_->builder().hit_rounding_scale();
  const uint32_t brick_count = store_->brick_count();
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
    known_resident.assign(brick_count, 0);
    mark_known_resident(cache_->resident_bricks());
  }
  const CacheCounters counters_before = cache_->counters();
  const std::size_t n = rays.size();
  QueryStats stats;
  stats.rays = n;

  std::unique_ptr<Scratch> scratch = take_scratch();
  struct GiveBack {
    QueryEngine* engine;
    std::unique_ptr<Scratch>& scratch;
    ~GiveBack() { engine->give_back_scratch(std::move(scratch)); }
  } give_back{this, scratch};
  // In-cache sweep: when every brick is resident and the budget holds the
  // scene (nothing can be evicted), queueing the whole batch at bricks buys
  // no reuse; each task instead takes a chunk of consecutive rays through all
  // their bricks, round by round, with the chunk's per-ray state kept in the
  // thread's cache. Each ray visits the same bricks in the same order with
  // the same hit so far, so answers are the same as queued.
  // Only for scenes of a few bricks: with many, a chunk's rays spread over
  // so many bricks that each visit starts cold in a brick's structure, and
  // queueing the whole batch at each brick is faster (measured: the 732-brick
  // city twice as slow swept; docs/BENCHMARKS.md).
  const bool all_resident = cache_fits_scene_ && cache_->counters().resident_bricks == brick_count;
  // The resident bricks' one Embree scene (below): for scenes of a few
  // bricks, like the sweep, and batches large enough to repay building it.
  const bool in_set = options.reorder && options.brick_set && embree_bricks_ && all_resident &&
                      brick_count > 0 && brick_count <= kSweepMaxBricks && n >= options.brick_set_min_rays;
  const bool sweep =
      !in_set && options.reorder && options.in_cache_sweep && all_resident && brick_count <= kSweepMaxBricks;
  // The in-cache sweep validates rays in its own chunks, and the queues in
  // the chunks of their first upper pass (one pass less over the rays'
  // memory), except in strict mode, where a bad ray must stop the batch
  // before anything is traced.
  const bool validate_apart = !options.reorder || options.strict;
  // Grown only (new elements are value-initialised once); every element
  // below n is overwritten below, in parallel.
  // The set and the sweep take chunks of consecutive rays with their own
  // per-ray state: no flags or progress records for the whole batch.
  const bool chunked = sweep || in_set;
  if ((!chunked || validate_apart) && scratch->valid.size() < n) scratch->valid.resize(n);
  if (!chunked && scratch->progress.size() < n) scratch->progress.resize(n);
  std::vector<uint8_t>& valid = scratch->valid;
  std::vector<RayProgress>& progress = scratch->progress;
  const FlatLeaves& flat = upper_walks_->flat;
  const bool use_flat = upper_walks_->use_flat;
  const WideUpper& wide = upper_walks_->wide;
  const WideUpper8& wide8 = upper_walks_->wide8;
  const bool use_avx = options.avx_upper && cpu_has_avx();
  // The ray's next window: flat, 8-wide with AVX, else 4-wide.
  auto next_window = [&](const SlabRay& slab_ray, float tmin, float limit, RayProgress& p,
                         AdvanceCounters& counters) -> uint32_t {
    if (use_flat) return next_bricks_flat(flat, slab_ray, tmin, limit, p.last, p.window, counters.nodes);
    if (use_avx) return next_bricks_wide8(wide8, slab_ray, tmin, limit, p.last, p.window, counters.nodes);
    return next_bricks_wide(wide, slab_ray, tmin, limit, p.last, p.window, counters.nodes);
  };

  // Ray i's answer before tracing (a miss), and whether it is a hit after.
  auto reset_answer = [&](std::size_t i) {
    if constexpr (kKind == QueryKind::kClosestHit) {
      hits[i] = Hit{};
    } else {
      occluded[i] = 0;
    }
  };
  auto answered_hit = [&](std::size_t i) -> uint64_t {
    if constexpr (kKind == QueryKind::kClosestHit) return hits[i].is_hit();
    return occluded[i] != 0;
  };
  // Resets ray i's answer; true when the ray is valid (ray_problem).
  auto reset_and_check = [&](std::size_t i) {
    reset_answer(i);
    return ray_problem(rays[i]) == nullptr;
  };
  // In the chunked paths: whether ray i is to be traced. Validated apart, its
  // flag says; otherwise it is reset and checked here, and counted in
  // `invalid` when it is bad.
  auto chunk_ray_valid = [&](std::size_t i, uint64_t& invalid) {
    if (validate_apart) return valid[i] != 0;
    if (reset_and_check(i)) return true;
    ++invalid;
    return false;
  };

  // Validation and reset of the outputs and per-ray progress, in parallel
  // chunks; the first bad ray of each chunk is kept so that strict mode names
  // the first of the batch.
  const std::size_t check_chunks = validate_apart ? (n + kCheckGrain - 1) / kCheckGrain : 0;
  std::vector<uint64_t> chunk_invalid(check_chunks, 0);
  std::vector<std::size_t> chunk_first_bad(check_chunks, n);
  tbb::parallel_for(std::size_t{0}, check_chunks, [&](std::size_t c) {
    const std::size_t end = std::min(n, (c + 1) * kCheckGrain);
    for (std::size_t i = c * kCheckGrain; i < end; ++i) {
      const bool ok = reset_and_check(i);
      valid[i] = ok;
      if (!ok) {
        if (chunk_first_bad[c] == n) chunk_first_bad[c] = i;
        ++chunk_invalid[c];
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
  const bool track_demand = options.reorder && !sweep && cache_->wants_schedule_hint();
  std::vector<std::atomic<uint32_t>> demand(track_demand ? brick_count : 0);
  // Trace-ahead (below) is possible only when the budget cannot hold the scene.
  const bool ahead_possible = options.reorder && options.trace_ahead && !cache_fits_scene_;
  std::vector<std::array<uint32_t, kWindow>>& ahead_state = scratch->ahead_state;
  if (ahead_possible && ahead_state.size() < n) ahead_state.resize(n);
  // Entries traced ahead already gave their demand back (trace_ahead below).
  auto drop_window = [&](RayProgress& p, std::size_t i) {
    if (!track_demand) return;
    for (; p.next < p.count; ++p.next) {
      if (!ahead_possible || ahead_state[i][p.next] == kAheadNone)
        demand[p.window[p.next].brick].fetch_sub(1, std::memory_order_relaxed);
    }
  };
  std::vector<Hit>& ahead_hits = scratch->ahead_hits;
  ahead_hits.clear();
  // Ray i's window was just filled with `found` keys: nothing of it used yet.
  auto begin_window = [&](RayProgress& p, std::size_t i, uint32_t found) {
    p.count = static_cast<uint8_t>(found);
    p.complete = p.count < kWindow;
    p.next = 0;
    if (ahead_possible) ahead_state[i] = {};
    p.listed = 0;
    if (track_demand) {
      for (uint8_t k = 0; k < p.count; ++k) demand[p.window[k].brick].fetch_add(1, std::memory_order_relaxed);
    }
  };
  // Moves ray i past its current brick; returns the next brick or kInvalidId.
  // A brick whose proxy the ray's remaining segment cannot hit is passed over
  // like a traced brick without a hit (it has none to give), so the ray's
  // hit, horizon and brick order are what they are with proxies off. A brick
  // the ray was traced against ahead of its turn is passed over too, its hit
  // (if any) taken now: the visit happens, only earlier.
  // `p` is ray i's progress record (progress[i], or the in-cache sweep's own).
  auto advance_with = [&](RayProgress& p, std::size_t i, AdvanceCounters& counters) -> uint32_t {
    float limit = horizon(i);
    for (;;) {
      if (finished(i)) {
        drop_window(p, i);
        return kInvalidId;
      }
      BrickKey key;
      uint32_t ahead = kAheadNone;
      if (p.next < p.count) {
        key = p.window[p.next];
        if (key.entry > limit) {
          drop_window(p, i);
          return kInvalidId;
        }
        if (ahead_possible) ahead = ahead_state[i][p.next];
        p.last = key;
        ++p.next;
      } else {
        if (p.complete) return kInvalidId;
        const SlabRay slab_ray(rays[i]);
        begin_window(p, i, next_window(slab_ray, rays[i].tnear, limit, p, counters));
        if (p.count == 0) return kInvalidId;
        key = p.window[0];
        p.last = key;
        p.next = 1;
      }
      if (ahead != kAheadNone) {
        if (ahead == kAheadSkip) {
          ++counters.skipped;
          continue;
        }
        ++counters.ahead_visits;
        if constexpr (kKind == QueryKind::kClosestHit) {
          if (ahead >= kAheadHitBase) {
            const Hit& found = ahead_hits[ahead - kAheadHitBase];
            if (hit_is_better(found.t, found.geometry_id, found.primitive_id, hits[i])) hits[i] = found;
            limit = horizon(i);
          }
        }
        continue;
      }
      if (proxies == nullptr || (!known_resident.empty() && known_resident[key.brick])) return key.brick;
      ++counters.proxy_tests;
      const uint64_t t0 = ticks();
      const bool may_hit = proxies->brick(key.brick).may_hit(rays[i], rays[i].tnear, limit, hit_rounding);
      counters.proxy_ticks += ticks() - t0;
      if (may_hit) return key.brick;
      ++counters.skipped;
      // Passed over: the ray no longer needs the brick.
      if (track_demand) demand[key.brick].fetch_sub(1, std::memory_order_relaxed);
    }
  };
  auto advance = [&](std::size_t i, AdvanceCounters& counters) {
    return advance_with(progress[i], i, counters);
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

  // The per-ray state advance() reads, fetched a few rays ahead: a queue's
  // rays are scattered over the batch, and advance() otherwise stalls on
  // each ray's progress record.
  auto prefetch_ray_state = [&](uint32_t ray) {
    __builtin_prefetch(&progress[ray]);
    __builtin_prefetch(reinterpret_cast<const char*>(&progress[ray]) + sizeof(RayProgress) - 1);
    if constexpr (kKind == QueryKind::kClosestHit) __builtin_prefetch(&hits[ray].t);
  };
  // Traces the rays `ids` queued at `brick` there, then moves each to its
  // next brick, collecting (next brick, ray) in `moved` for the scheduler.
  auto trace_and_advance = [&](uint32_t brick, const BrickAccel& accel, std::span<const uint32_t> ids,
                               AdvanceCounters& counters, std::vector<std::pair<uint32_t, uint32_t>>& moved) {
    trace(accel, ids);
    if (track_demand) demand[brick].fetch_sub(static_cast<uint32_t>(ids.size()), std::memory_order_relaxed);
    for (std::size_t k = 0; k < ids.size(); ++k) {
      if (k + kAdvancePrefetch < ids.size()) prefetch_ray_state(ids[k + kAdvancePrefetch]);
      const uint32_t ray = ids[k];
      const uint32_t next = advance(ray, counters);
      if (next != kInvalidId) {
        moved.emplace_back(next, ray);
      } else {
        // A ray with a brick finishes here, once, after its last brick
        // (a ray without one, or an invalid one, cannot hit): counted while
        // its answer is in the cache, not by a pass over the batch's hits.
        counters.rays_hit += answered_hit(ray);
      }
    }
  };

  if (!options.reorder) {
    // One ray at a time, in input order, brick by brick.
    for (std::size_t i = 0; i < n; ++i) {
      if (!valid[i]) continue;
      if (cancel_requested()) return interrupted();
      progress[i] = RayProgress{};
      const uint32_t id = static_cast<uint32_t>(i);
      const auto t0 = Clock::now();
      AdvanceCounters counters;
      for (uint32_t brick = advance(i, counters); brick != kInvalidId; brick = advance(i, counters)) {
        PinnedBrick pin;
        OUTCORE_RETURN_IF_ERROR(acquire(brick, pin));
        trace(pin.accel(), std::span<const uint32_t>(&id, 1));
        ++stats.brick_visits;
      }
      stats.rays_hit += answered_hit(i);
      counters.add_to(stats);
      proxy_ticks += counters.proxy_ticks;
      stats.seconds_brick += seconds_since(t0);
    }
  } else if (in_set) {
    // Every brick pinned for the batch (cache hits: all are resident), then
    // one Embree scene over them all; chunks of consecutive rays go through
    // it as they would through one brick.
    std::vector<PinnedBrick> pins(brick_count);
    std::vector<const EmbreeBrickAccel*> accels(brick_count);
    for (uint32_t b = 0; b < brick_count; ++b) {
      OUTCORE_RETURN_IF_ERROR(acquire(b, pins[b]));
      accels[b] = static_cast<const EmbreeBrickAccel*>(&pins[b].accel());  // embree_bricks_
    }
    const auto t_set = Clock::now();
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<EmbreeBrickSet> set, EmbreeBrickSet::build(accels));
    stats.seconds_upper += seconds_since(t_set);
    const auto t_trace = Clock::now();
    const std::size_t chunks = (n + kSweepRays - 1) / kSweepRays;
    std::vector<std::array<uint64_t, 3>> chunk_counts(chunks);  // traced, invalid, hit
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::array<uint32_t, kSweepRays> ids;
      const std::size_t base = c * kSweepRays;
      const std::size_t size = std::min(n - base, kSweepRays);
      std::size_t count = 0;
      uint64_t invalid = 0;
      for (std::size_t i = base; i < base + size; ++i) {
        if (chunk_ray_valid(i, invalid)) ids[count++] = static_cast<uint32_t>(i);
      }
      const std::span<const uint32_t> traced(ids.data(), count);
      if constexpr (kKind == QueryKind::kClosestHit) {
        set->intersect(traced, rays.data(), hits);
      } else {
        set->occluded(traced, rays.data(), occluded);
      }
      uint64_t hit = 0;
      for (const uint32_t i : traced) hit += answered_hit(i);
      chunk_counts[c] = {count, invalid, hit};
    });
    for (const auto& [traced, invalid, hit] : chunk_counts) {
      stats.rays_in_brick_set += traced;
      if (!validate_apart) stats.invalid_rays += invalid;
      stats.rays_hit += hit;
    }
    stats.seconds_brick += seconds_since(t_trace);
  } else if (sweep) {
    // Each brick is pinned by the first task to reach it and held to the end
    // of the batch (a cache hit: all are resident); one lock per brick per
    // batch, never per ray.
    std::vector<PinnedBrick> pins(brick_count);
    std::vector<std::atomic<const BrickAccel*>> pinned(brick_count);
    std::mutex pin_mutex;
    Status pin_status;
    std::atomic<bool> pin_failed{false};
    auto pinned_accel = [&](uint32_t brick) -> const BrickAccel* {
      const BrickAccel* accel = pinned[brick].load(std::memory_order_acquire);
      if (accel != nullptr) return accel;
      std::lock_guard<std::mutex> lock(pin_mutex);
      accel = pinned[brick].load(std::memory_order_relaxed);
      if (accel != nullptr) return accel;
      // Isolated: should another batch have evicted the brick, its build must
      // not pick up one of this batch's tasks, which could wait on this lock.
      const Status status = tbb::this_task_arena::isolate([&] { return acquire(brick, pins[brick]); });
      if (!status.ok()) {
        if (pin_status.ok()) pin_status = status;
        pin_failed.store(true, std::memory_order_relaxed);
        return nullptr;
      }
      accel = &pins[brick].accel();
      pinned[brick].store(accel, std::memory_order_release);
      return accel;
    };
    struct SweepTask {
      AdvanceCounters counters;
      uint64_t visits = 0;
      uint64_t ticks = 0;        // the whole task
      uint64_t trace_ticks = 0;  // inside bricks
      uint64_t invalid = 0;
      uint64_t hit = 0;
    };
    const std::size_t chunks = (n + kSweepRays - 1) / kSweepRays;
    std::vector<SweepTask> sweep_tasks(chunks);
    const auto t_sweep = Clock::now();
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      const uint64_t task_start = ticks();
      SweepTask& task = sweep_tasks[c];
      SweepScratch& local = scratch->sweep.local();
      if (local.group_end.size() < brick_count) local.group_end.assign(brick_count, 0);
      const std::size_t base = c * kSweepRays;
      const std::size_t size = std::min(n - base, kSweepRays);
      std::size_t active = 0;
      for (std::size_t k = 0; k < size; ++k) {
        if (!chunk_ray_valid(base + k, task.invalid)) continue;
        local.progress[k] = RayProgress{};
        const uint32_t brick = advance_with(local.progress[k], base + k, task.counters);
        if (brick == kInvalidId) continue;
        local.at[k] = brick;
        local.active[active++] = static_cast<uint32_t>(k);
      }
      // Rounds: the active rays are grouped by their brick (a counting sort,
      // stable, so each group keeps input order), each group is traced, and
      // each ray moves on to its next brick.
      while (active > 0 && !pin_failed.load(std::memory_order_relaxed)) {
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
        active = 0;
        uint32_t begin = 0;
        for (const uint32_t brick : local.touched) {
          const uint32_t end = local.group_end[brick];
          local.group_end[brick] = 0;
          const std::span<const uint32_t> ids(local.grouped.data() + begin, end - begin);
          begin = end;
          const BrickAccel* accel = pinned_accel(brick);
          if (accel == nullptr) continue;  // the batch fails: the error is returned below
          const uint64_t trace_start = ticks();
          trace(*accel, ids);
          task.trace_ticks += ticks() - trace_start;
          task.visits += ids.size();
          for (const uint32_t ray : ids) {
            const uint32_t k = ray - static_cast<uint32_t>(base);
            const uint32_t next = advance_with(local.progress[k], ray, task.counters);
            if (next == kInvalidId) continue;
            local.at[k] = next;
            local.active[active++] = k;
          }
        }
      }
      for (std::size_t i = base; i < base + size; ++i) task.hit += answered_hit(i);
      task.ticks = ticks() - task_start;
    });
    OUTCORE_RETURN_IF_ERROR(pin_status);
    uint64_t task_ticks = 0, trace_ticks = 0;
    for (const SweepTask& task : sweep_tasks) {
      task.counters.add_to(stats);
      proxy_ticks += task.counters.proxy_ticks;
      stats.brick_visits += task.visits;
      if (!validate_apart) stats.invalid_rays += task.invalid;
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
  } else {
    std::vector<std::vector<uint32_t>>& queues = scratch->queues;
    if (queues.size() < brick_count) queues.resize(brick_count);
    for (auto& queue : queues) queue.clear();  // a failed batch may have left rays
    std::vector<uint32_t> waiting;             // bricks with a non-empty queue
    std::vector<uint8_t> is_waiting(brick_count, 0);
    // Trace-ahead: under a budget that cannot hold the scene, a brick built
    // for its queue may be evicted before the rays that reach it later (those
    // with it further on in their window) get there, and be built again. So
    // when a build may evict, the rays with the brick further on are traced
    // against it too, while it is pinned, and the outcome is kept for when
    // they get there (RayProgress::ahead). A closest hit found ahead is taken
    // only when the ray reaches the brick, by hit_is_better(), which is what
    // tracing it then would give (the brick's best hit does not depend on how
    // far the ray was clipped when it was traced), so answers stay bitwise
    // the same; an any-hit found ahead finishes the ray at once (occlusion is
    // an OR over bricks).
    std::vector<std::vector<uint32_t>>& upcoming = scratch->upcoming;
    if (ahead_possible) {
      if (upcoming.size() < brick_count) upcoming.resize(brick_count);
      for (auto& list : upcoming) list.clear();
    }
    auto list_upcoming = [&](uint32_t ray) {
      RayProgress& p = progress[ray];
      for (uint8_t k = p.next; k < p.count; ++k) {
        if (p.listed & (1u << k)) continue;
        p.listed |= static_cast<uint8_t>(1u << k);
        upcoming[p.window[k].brick].push_back(ray);
      }
    };
    auto enqueue = [&](uint32_t brick, uint32_t ray) {
      queues[brick].push_back(ray);
      if (!is_waiting[brick]) {
        is_waiting[brick] = 1;
        waiting.push_back(brick);
      }
      if (ahead_possible) list_upcoming(ray);
    };
    // Trace-ahead candidates of the bricks being built (concatenated), their
    // window entries, and the outcomes.
    std::vector<uint32_t> ahead_rays;
    std::vector<uint8_t> ahead_slots;
    std::vector<AdvanceCounters> ahead_counters;
    // Appends the rays listed at `brick` that have not reached it yet (one
    // per (ray, entry) however often it was listed; not those beyond their
    // horizon, which will never reach it) and marks their entries taken.
    // Rays whose current brick is in `busy` are left out: they are being
    // traced there at the same time.
    auto select_ahead = [&](uint32_t brick, std::span<const uint32_t> busy) {
      for (const uint32_t ray : upcoming[brick]) {
        RayProgress& p = progress[ray];
        if (finished(ray)) continue;
        if (std::find(busy.begin(), busy.end(), p.last.brick) != busy.end()) continue;
        for (uint8_t k = p.next; k < p.count; ++k) {
          if (p.window[k].brick != brick) continue;
          if (ahead_state[ray][k] == kAheadNone && p.window[k].entry <= horizon(ray)) {
            ahead_state[ray][k] = kAheadNoGain;
            ahead_rays.push_back(ray);
            ahead_slots.push_back(k);
          }
          break;
        }
      }
      upcoming[brick].clear();
    };
    auto reserve_ahead = [&](std::size_t m) {
      if (scratch->ahead_ray_copies.size() < m) scratch->ahead_ray_copies.resize(m);
      if (scratch->ahead_outcomes.size() < m) scratch->ahead_outcomes.resize(m);
      if constexpr (kKind == QueryKind::kClosestHit) {
        if (scratch->ahead_hit_copies.size() < m) scratch->ahead_hit_copies.resize(m);
      } else {
        if (scratch->ahead_occluded.size() < m) scratch->ahead_occluded.resize(m);
      }
    };
    // Traces candidates [begin, end) against `brick` on copies of their rays
    // and hits (the rays themselves are not at the brick yet); writes only
    // those copies and the outcomes.
    auto trace_ahead_range = [&](uint32_t brick, const BrickAccel& accel, std::size_t begin, std::size_t end,
                                 AdvanceCounters& counters) {
      Ray* const ray_copies = scratch->ahead_ray_copies.data();
      Hit* const hit_copies = scratch->ahead_hit_copies.data();
      uint8_t* const occluded_copies = scratch->ahead_occluded.data();
      uint32_t* const outcomes = scratch->ahead_outcomes.data();
      for (std::size_t from = begin; from < end; from += kRayGrain) {
        uint32_t ids[kRayGrain];
        std::size_t traced = 0;
        for (std::size_t j = from; j < std::min(end, from + kRayGrain); ++j) {
          const uint32_t ray = ahead_rays[j];
          if (proxies != nullptr) {
            ++counters.proxy_tests;
            const uint64_t t0 = ticks();
            const bool may_hit =
                proxies->brick(brick).may_hit(rays[ray], rays[ray].tnear, horizon(ray), hit_rounding);
            counters.proxy_ticks += ticks() - t0;
            if (!may_hit) {
              outcomes[j] = kAheadSkip;
              continue;
            }
          }
          outcomes[j] = kAheadNoGain;
          ray_copies[j] = rays[ray];
          if constexpr (kKind == QueryKind::kClosestHit) {
            hit_copies[j] = hits[ray];
          } else {
            occluded_copies[j] = 0;
          }
          ids[traced++] = static_cast<uint32_t>(j);
        }
        const std::span<const uint32_t> traced_ids(ids, traced);
        if constexpr (kKind == QueryKind::kClosestHit) {
          accel.intersect(traced_ids, ray_copies, hit_copies);
          for (const uint32_t j : traced_ids) {
            const Hit& found = hit_copies[j];
            if (hit_is_better(found.t, found.geometry_id, found.primitive_id, hits[ahead_rays[j]]))
              outcomes[j] = kAheadHitBase;
          }
        } else {
          accel.occluded(traced_ids, ray_copies, occluded_copies);
          for (const uint32_t j : traced_ids) {
            if (occluded_copies[j] != 0) outcomes[j] = kAheadHitBase;
          }
        }
        counters.ahead_traces += traced;
      }
    };
    // Files the outcomes in the rays' windows (serially: hits found ahead go
    // to one table). An occlusion found ahead finishes its ray now.
    auto file_ahead = [&]() {
      const uint32_t* const outcomes = scratch->ahead_outcomes.data();
      for (std::size_t j = 0; j < ahead_rays.size(); ++j) {
        const uint32_t ray = ahead_rays[j];
        uint32_t outcome = outcomes[j];
        if (outcome == kAheadHitBase) {
          if constexpr (kKind == QueryKind::kClosestHit) {
            outcome = kAheadHitBase + static_cast<uint32_t>(ahead_hits.size());
            ahead_hits.push_back(scratch->ahead_hit_copies[j]);
          } else {
            occluded[ray] = 1;
            outcome = kAheadNoGain;
          }
        }
        const RayProgress& p = progress[ray];
        if (track_demand) demand[p.window[ahead_slots[j]].brick].fetch_sub(1, std::memory_order_relaxed);
        ahead_state[ray][ahead_slots[j]] = outcome;
      }
      for (const AdvanceCounters& counters : ahead_counters) {
        counters.add_to(stats);
        proxy_ticks += counters.proxy_ticks;
      }
      ahead_rays.clear();
      ahead_slots.clear();
    };
    // Trace-ahead at one pinned brick, in parallel chunks.
    auto trace_ahead = [&](uint32_t brick, const BrickAccel& accel) {
      select_ahead(brick, {});
      const std::size_t m = ahead_rays.size();
      reserve_ahead(m);
      const std::size_t ahead_chunks = (m + kRayGrain - 1) / kRayGrain;
      ahead_counters.assign(ahead_chunks, AdvanceCounters{});
      tbb::this_task_arena::isolate([&] {
        tbb::parallel_for(std::size_t{0}, ahead_chunks, [&](std::size_t c) {
          trace_ahead_range(brick, accel, c * kRayGrain, std::min(m, (c + 1) * kRayGrain), ahead_counters[c]);
        });
      });
      file_ahead();
    };

    // First brick of every ray, in parallel; per-chunk results merged in order.
    const auto t_upper = Clock::now();
    const bool use_packet = !use_flat && use_avx;
    if (scratch->first.size() < n) scratch->first.resize(n);
    std::vector<uint32_t>& first = scratch->first;
    // Rays i .. i+7 through the upper hierarchy together when their
    // directions share an octant (rays of neighbouring pixels; random rays
    // rarely do); false, with nothing done, when they do not.
    auto first_windows_by_packet = [&](std::size_t i, AdvanceCounters& counters) -> bool {
      constexpr uint32_t kLanes = SlabPacket::kLanes;
      uint32_t lanes = 0;
      int octant = -1;
      for (uint32_t lane = 0; lane < kLanes; ++lane) {
        if (!valid[i + lane]) continue;
        const Vec3f& d = rays[i + lane].direction;
        const int o = int(std::signbit(d.x)) | int(std::signbit(d.y)) << 1 | int(std::signbit(d.z)) << 2;
        if (octant >= 0 && o != octant) return false;
        octant = o;
        lanes |= 1u << lane;
      }
      if (__builtin_popcount(lanes) < 2) return false;
      SlabPacket packet;
      std::array<std::array<BrickKey, kWindow>*, kLanes> windows;
      for (uint32_t lane = 0; lane < kLanes; ++lane) {
        const std::size_t r = i + lane;
        progress[r] = RayProgress{};
        windows[lane] = &progress[r].window;
        // Unused lanes get a copy of a used one: computed, never reported.
        const std::size_t from =
            (lanes >> lane & 1u) ? r : i + static_cast<std::size_t>(__builtin_ctz(lanes));
        packet.set(lane, rays[from], rays[from].tnear, horizon(from));
      }
      uint32_t found[kLanes];
      first_bricks_wide_packet(wide, packet, lanes, windows.data(), found, counters.nodes);
      for (uint32_t lane = 0; lane < kLanes; ++lane) {
        const std::size_t r = i + lane;
        if (!(lanes >> lane & 1u)) {
          first[r] = kInvalidId;
          continue;
        }
        begin_window(progress[r], r, found[lane]);
        first[r] = advance(r, counters);
      }
      return true;
    };
    const std::size_t chunks = (n + kRayGrain - 1) / kRayGrain;
    std::vector<AdvanceCounters> chunk_counters(chunks);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      AdvanceCounters counters;
      const std::size_t end = std::min(n, (c + 1) * kRayGrain);
      if (!validate_apart) {
        for (std::size_t i = c * kRayGrain; i < end; ++i) {
          valid[i] = reset_and_check(i);
          counters.invalid_rays += !valid[i];
        }
      }
      for (std::size_t i = c * kRayGrain; i < end;) {
        if (use_packet && i + SlabPacket::kLanes <= end && first_windows_by_packet(i, counters)) {
          i += SlabPacket::kLanes;
          continue;
        }
        // Reset here, not in the validation pass: one pass over this memory.
        progress[i] = RayProgress{};
        first[i] = valid[i] ? advance(i, counters) : kInvalidId;
        ++i;
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
    // What a parallel task that takes a brick from the cache reports.
    struct PinningTask {
      AdvanceCounters counters;
      double build_seconds = 0;
      bool was_hit = false;
      Status status;
    };
    // Takes `brick` from the cache for `task`; nullopt (the error kept in
    // the task) when it cannot be had.
    auto pin_for = [&](uint32_t brick, PinningTask& task) -> std::optional<PinnedBrick> {
      const auto t0 = Clock::now();
      auto acquired = cache_->acquire(brick);
      task.build_seconds = seconds_since(t0);
      if (!acquired.ok()) {
        task.status = acquired.status();
        return std::nullopt;
      }
      task.was_hit = acquired->was_hit();
      return std::move(acquired).value();
    };
    // Adds a finished task's figures to the batch's (in task order).
    auto merge = [&](const PinningTask& task) {
      task.counters.add_to(stats);
      proxy_ticks += task.counters.proxy_ticks;
      ++stats.brick_acquisitions;
      ++(task.was_hit ? stats.cache_hits : stats.cache_misses);
    };
    // One task of a wave: a chunk of one resident brick's queue.
    struct WaveTask : PinningTask {
      uint32_t brick;
      uint32_t queue;  // index into wave_batches
      std::size_t begin, end;
    };
    std::vector<WaveTask> tasks;
    std::vector<std::vector<uint32_t>>& wave_batches = scratch->wave_batches;
    std::vector<uint32_t> resident_now, not_resident;
    std::vector<uint32_t> schedule_hint;
    // Bricks built at once when nothing waiting is resident, one task each.
    struct BuildTask : PinningTask {
      double seconds = 0;  // the whole task
    };
    const std::size_t build_slots = static_cast<std::size_t>(
        std::max(1, std::min<int>(tbb::this_task_arena::max_concurrency(),
                                  static_cast<int>(tbb::global_control::active_value(
                                      tbb::global_control::max_allowed_parallelism)))));
    const std::size_t loop_bricks = static_cast<std::size_t>(std::max<uint64_t>(
        build_slots,
        std::min<uint64_t>(build_slots * kBuildsPerThread, bricks_budget_holds_ / kBudgetBricksPerLoop)));
    std::vector<uint32_t> building;
    std::vector<BuildTask> build_tasks;
    std::vector<std::size_t> ahead_begin;
    while (!waiting.empty()) {
      if (cancel_requested()) return interrupted();
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
          const std::optional<PinnedBrick> pin = pin_for(task.brick, task);
          if (!pin) return;
          const std::vector<uint32_t>& batch = wave_batches[task.queue];
          const std::span<const uint32_t> ids(batch.data() + task.begin, task.end - task.begin);
          trace_and_advance(task.brick, pin->accel(), ids, task.counters, moved[t]);
        });
        for (std::size_t t = 0; t < tasks.size(); ++t) {
          const WaveTask& task = tasks[t];
          OUTCORE_RETURN_IF_ERROR(task.status);
          merge(task);
          stats.seconds_build += task.build_seconds;
          for (const auto& [next, ray] : moved[t]) enqueue(next, ray);
        }
        // Once the cache has had to evict, a resident brick may be gone when
        // the rays with it further on get there: they are traced now.
        if (ahead_possible && cache_->counters().evictions > counters_before.evictions) {
          for (const uint32_t b : resident_now) {
            // One a concurrent batch has evicted since is not rebuilt for
            // this: its listed rays stay listed for when it is built again.
            if (upcoming[b].empty() || !cache_->is_resident(b)) continue;
            PinnedBrick pin;
            OUTCORE_RETURN_IF_ERROR(acquire(b, pin));
            trace_ahead(b, pin.accel());
          }
        }
        stats.seconds_brick += seconds_since(t_brick);
        continue;
      }

      // Nothing waiting is resident: build the bricks with the longest
      // queues, at least as many as there are threads (a brick's load and
      // build are mostly serial, so one build at a time would leave cores
      // idle) and up to kBuildsPerThread each, then trace their rays.
      const std::size_t want = std::min<std::size_t>(loop_bricks, waiting.size());
      std::partial_sort(waiting.begin(), waiting.begin() + static_cast<std::ptrdiff_t>(want), waiting.end(),
                        [&](uint32_t a, uint32_t b) {
                          const std::size_t qa = queues[a].size(), qb = queues[b].size();
                          return qa != qb ? qa > qb : a < b;
                        });
      building.assign(waiting.begin(), waiting.begin() + static_cast<std::ptrdiff_t>(want));
      waiting.erase(waiting.begin(), waiting.begin() + static_cast<std::ptrdiff_t>(want));
      if (wave_batches.size() < want) wave_batches.resize(want);
      uint64_t building_reserve = 0;
      for (std::size_t q = 0; q < want; ++q) {
        const uint32_t b = building[q];
        is_waiting[b] = 0;
        wave_batches[q].swap(queues[b]);
        queues[b].clear();
        stats.brick_visits += wave_batches[q].size();
        building_reserve += cache_->builder().reserve_bytes(store_->manifest().bricks[b].triangle_count);
      }

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
      // Builds that may evict: the cache is full or has evicted during this
      // batch.
      bool ahead_now = false;
      if (ahead_possible) {
        const CacheCounters now = cache_->counters();
        ahead_now = now.evictions > counters_before.evictions ||
                    now.resident_bytes + building_reserve > cache_->budget_bytes();
      }
      const auto t_brick = Clock::now();

      if (want == 1) {
        // One brick: its rays are traced in parallel chunks.
        const uint32_t brick = building[0];
        const std::vector<uint32_t>& batch = wave_batches[0];
        PinnedBrick pin;
        OUTCORE_RETURN_IF_ERROR(acquire(brick, pin));
        if (!known_resident.empty()) known_resident[brick] = 1;
        const BrickAccel& accel = pin.accel();
        const std::size_t batch_chunks = (batch.size() + kRayGrain - 1) / kRayGrain;
        moved.resize(std::max(moved.size(), batch_chunks));
        chunk_counters.assign(batch_chunks, AdvanceCounters{});
        // Isolated: a thread waiting here while the brick is pinned must not
        // pick up another batch's task that could wait on the cache.
        tbb::this_task_arena::isolate([&] {
          tbb::parallel_for(std::size_t{0}, batch_chunks, [&](std::size_t c) {
            const std::size_t begin = c * kRayGrain, end = std::min(batch.size(), begin + kRayGrain);
            const std::span<const uint32_t> ids(batch.data() + begin, end - begin);
            moved[c].clear();
            AdvanceCounters counters;
            trace_and_advance(brick, accel, ids, counters, moved[c]);
            chunk_counters[c] = counters;
          });
        });
        for (std::size_t c = 0; c < batch_chunks; ++c) {
          chunk_counters[c].add_to(stats);
          proxy_ticks += chunk_counters[c].proxy_ticks;
          for (const auto& [next, ray] : moved[c]) enqueue(next, ray);
        }
        if (ahead_now) trace_ahead(brick, accel);
        pin.release();
        stats.seconds_brick += seconds_since(t_brick);
        continue;
      }

      // Several bricks: one task each loads, builds and pins its brick,
      // traces its queue and its trace-ahead candidates (chosen here, among
      // rays not queued at any of these bricks, so that no two tasks touch
      // one ray), and unpins. Like a wave task it never waits while pinned.
      ahead_begin.assign(want + 1, 0);
      if (ahead_now) {
        for (std::size_t q = 0; q < want; ++q) {
          ahead_begin[q] = ahead_rays.size();
          select_ahead(building[q], building);
        }
      }
      ahead_begin[want] = ahead_rays.size();
      reserve_ahead(ahead_rays.size());
      ahead_counters.assign(want, AdvanceCounters{});
      build_tasks.assign(want, BuildTask{});
      moved.resize(std::max(moved.size(), want));
      tbb::parallel_for(std::size_t{0}, want, [&](std::size_t q) {
        BuildTask& task = build_tasks[q];
        moved[q].clear();
        const uint32_t brick = building[q];
        const auto t0 = Clock::now();
        const std::optional<PinnedBrick> pin = pin_for(brick, task);
        if (!pin) return;
        trace_and_advance(brick, pin->accel(), wave_batches[q], task.counters, moved[q]);
        trace_ahead_range(brick, pin->accel(), ahead_begin[q], ahead_begin[q + 1], ahead_counters[q]);
        task.seconds = seconds_since(t0);
      });
      double task_build_seconds = 0, task_seconds = 0;
      for (std::size_t q = 0; q < want; ++q) {
        const BuildTask& task = build_tasks[q];
        OUTCORE_RETURN_IF_ERROR(task.status);
        if (!known_resident.empty()) known_resident[building[q]] = 1;
        merge(task);
        task_build_seconds += task.build_seconds;
        task_seconds += task.seconds;
        for (const auto& [next, ray] : moved[q]) enqueue(next, ray);
      }
      file_ahead();
      // The tasks overlapped: their wall time is split between building and
      // tracing in the proportion of their own times.
      const double wall = seconds_since(t_brick);
      const double building_share = task_seconds > 0 ? task_build_seconds / task_seconds : 0;
      stats.seconds_build += wall * building_share;
      stats.seconds_brick += wall * (1 - building_share);
    }
  }

  // The batch's evicted bricks hold no pages past its end.
  cache_->release_evicted_pages();
  const CacheCounters counters_after = cache_->counters();
  stats.brick_builds = counters_after.builds - counters_before.builds;
  stats.evictions = counters_after.evictions - counters_before.evictions;
  const SubtreeTierCounters& tier_before = counters_before.subtree;
  const SubtreeTierCounters& tier_after = counters_after.subtree;
  stats.subtree_loads = tier_after.loads - tier_before.loads;
  stats.subtree_loads_checked = tier_after.loads_checked - tier_before.loads_checked;
  stats.subtree_loads_kept = tier_after.loads_kept - tier_before.loads_kept;
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

template Status QueryEngine::run<QueryKind::kClosestHit>(std::span<const Ray>, Hit*, uint8_t*,
                                                         const QueryOptions&, QueryStats*);
template Status QueryEngine::run<QueryKind::kAnyHit>(std::span<const Ray>, Hit*, uint8_t*,
                                                     const QueryOptions&, QueryStats*);

}  // namespace outcore
