#include "core/query/query_engine.h"

#include <algorithm>
#include <optional>

#include "core/cache/cache_budget.h"
#include "core/query/batch_planner.h"
#include "core/query/batch_scratch.h"
#include "core/query/point_queries.h"
#include "core/query/strategy.h"
#include "core/query/upper_walks.h"
#include "core/util/cpu_features.h"

namespace outcore {

QueryEngine::QueryEngine(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickCache> cache,
                         std::unique_ptr<const ProxySet> proxies, ProxyOpenReport proxy_report,
                         bool cache_fits_scene, uint64_t bricks_budget_holds,
                         DynamicTopLevel dynamic_top_level)
    : store_(std::move(store)),
      cache_(std::move(cache)),
      proxies_(std::move(proxies)),
      proxy_report_(std::move(proxy_report)),
      cache_fits_scene_(cache_fits_scene),
      bricks_budget_holds_(bricks_budget_holds),
      upper_walks_(std::make_unique<const UpperWalks>(store_->manifest().upper)),
      scratch_pool_(kKeptScratches, keep_batch_scratch),
      dynamic_(static_cast<uint32_t>(store_->manifest().inputs.size()), dynamic_top_level) {}

QueryEngine::~QueryEngine() = default;

Expected<std::unique_ptr<QueryEngine>> QueryEngine::open(const std::string& store_directory,
                                                         const EngineOptions& options) {
  OUTCORE_ASSIGN_OR_RETURN(auto store, SceneStore::open(store_directory));
  return create(std::move(store), options);
}

Expected<std::unique_ptr<QueryEngine>> QueryEngine::create(std::shared_ptr<const SceneStore> store,
                                                           const EngineOptions& options) {
  if (options.cache_bytes == 0) return invalid_argument("the cache budget must be positive");
  if (options.dynamic_top_level != "bvh" && options.dynamic_top_level != "bkd")
    return invalid_argument("--dynamic-top must be bvh or bkd, got '" + options.dynamic_top_level + "'");
  const DynamicTopLevel dynamic_top =
      options.dynamic_top_level == "bkd" ? DynamicTopLevel::kBkd : DynamicTopLevel::kBvh;
  BrickAccelOptions accel_options = options.accel_options;
  OUTCORE_ASSIGN_OR_RETURN(auto builder, make_brick_builder(options.brick_accel, accel_options));
  OUTCORE_ASSIGN_OR_RETURN(auto policy, make_eviction_policy(options.eviction_policy));
  const std::optional<BrickBoundKind> bound_kind = brick_bound_from_name(options.brick_bounds);
  if (!bound_kind) {
    return invalid_argument("unknown brick bound '" + options.brick_bounds + "' (known: aabb, sphere, obb)");
  }
  // Only the chosen bound's records are kept (none for aabb).
  std::vector<BoundingSphere> spheres;
  std::vector<OrientedBox> boxes;
  for (const BrickRecord& brick : store->manifest().bricks) {
    if (*bound_kind == BrickBoundKind::kSphere) spheres.push_back(brick.sphere);
    if (*bound_kind == BrickBoundKind::kObb) boxes.push_back(brick.obb);
  }
  auto bounds = std::make_unique<const BrickBounds>(*bound_kind, std::move(spheres), std::move(boxes),
                                                    builder->hit_rounding_scale());
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
  // The build quality is never changed behind the user's back, even under a
  // tight budget where a lower one would build faster: a ray running in an
  // axis plane (a zero direction component) along a mesh edge in that plane
  // hits one of the edge's two triangles or the other depending on which of
  // the tree's boxes have a face in the plane, so answers would depend on
  // the budget (QueryEngine.ABudgetBelowTheSceneKeepsTheBuildQualityAndEveryAnswer).
  auto cache =
      std::make_unique<BrickCache>(store, std::move(builder), std::move(policy), options.cache_bytes);
  if (options.access_trace) cache->set_access_trace(options.access_trace);
  if (!options.subtree_dir.empty())
    OUTCORE_RETURN_IF_ERROR(cache->enable_subtree_tier(
        {options.subtree_dir, options.subtree_max_bytes, options.subtree_release_batch_bytes}));
  auto engine = std::unique_ptr<QueryEngine>(
      new QueryEngine(std::move(store), std::move(cache), std::move(proxies), std::move(proxy_report),
                      cache_fits_scene, bricks_budget_holds, dynamic_top));
  engine->accel_options_ = std::move(accel_options);
  engine->bounds_ = std::move(bounds);
  return engine;
}

Status QueryEngine::intersect(std::span<const Ray> rays, std::span<Hit> hits, const QueryOptions& options,
                              QueryStats* stats) {
  if (hits.size() != rays.size()) return invalid_argument("hits and rays differ in length");
  return run<QueryKind::kClosestHit>(rays, {.hits = hits.data()}, options, stats);
}

Status QueryEngine::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded,
                             const QueryOptions& options, QueryStats* stats) {
  if (occluded.size() != rays.size()) return invalid_argument("occlusion flags and rays differ in length");
  return run<QueryKind::kAnyHit>(rays, {.occluded = occluded.data()}, options, stats);
}

namespace {

// FAILED_PRECONDITION when the dynamic layer holds instances: `what` sees
// the static scene only, and an answer without the layer would be wrong.
Status static_scene_only(const DynamicSnapshot& dynamic, const char* what) {
  if (dynamic.instances.empty()) return Status::Ok();
  return failed_precondition(std::string(what) + " see the static scene only, and the dynamic layer holds " +
                             std::to_string(dynamic.instances.size()) + " instance(s) at version " +
                             std::to_string(dynamic.version));
}

// `found` ordered by ray, then t, then ids, into `out`: placed by ray (a
// counting sort: each ray's place is known from how many records the rays
// before it have), then each ray's few records sorted in place. Linear in
// the records where one sort of them all was not.
void sort_by_ray_then_t(const std::vector<RayHitRecord>& found, std::size_t ray_count,
                        std::vector<RayHitRecord>& out) {
  std::vector<uint64_t> start(ray_count + 1, 0);
  for (const RayHitRecord& r : found) ++start[r.ray + 1];
  for (std::size_t i = 0; i < ray_count; ++i) start[i + 1] += start[i];
  out.resize(found.size());
  std::vector<uint64_t> next(start.begin(), start.end() - 1);
  for (const RayHitRecord& r : found) out[next[r.ray]++] = r;
  const auto before = [](const RayHitRecord& a, const RayHitRecord& b) {
    if (a.hit.t != b.hit.t) return a.hit.t < b.hit.t;
    if (a.hit.geometry_id != b.hit.geometry_id) return a.hit.geometry_id < b.hit.geometry_id;
    return a.hit.primitive_id < b.hit.primitive_id;
  };
  for (std::size_t i = 0; i < ray_count; ++i) {
    if (start[i + 1] - start[i] > 1) std::sort(out.begin() + start[i], out.begin() + start[i + 1], before);
  }
}

}  // namespace

Status QueryEngine::all_hits(std::span<const Ray> rays, std::span<uint32_t> counts,
                             std::vector<RayHitRecord>* records, const QueryOptions& options,
                             QueryStats* stats) {
  if (counts.size() != rays.size()) return invalid_argument("hit counts and rays differ in length");
  if (!options.only_bricks.empty()) {
    return invalid_argument(
        "only_bricks is for closest-hit and any-hit queries (Intersect, Occluded), not "
        "every-hit ones: leave it empty");
  }
  AllHitsCollector collector;
  // Neither the resident set nor trace-ahead keeps every hit.
  QueryOptions every_hit = options;
  every_hit.brick_set = false;
  every_hit.trace_ahead = false;
  OUTCORE_RETURN_IF_ERROR(run<QueryKind::kAllHits>(
      rays, {.hit_counts = counts.data(), .collector = records != nullptr ? &collector : nullptr}, every_hit,
      stats));
  if (records == nullptr) return Status::Ok();
  sort_by_ray_then_t(collector.records, rays.size(), *records);
  return Status::Ok();
}

Status QueryEngine::closest_points(std::span<const Vec3f> points, std::span<ClosestPoint> answers,
                                   const QueryOptions& options, QueryStats* stats_out) {
  if (answers.size() != points.size()) return invalid_argument("answers and points differ in length");
  OUTCORE_RETURN_IF_ERROR(static_scene_only(*dynamic_.latest(), "point queries"));
  const auto start = Clock::now();
  const uint64_t ticks_start = ticks();
  const CacheCounters counters_before = cache_->counters();
  BatchTally tally;
  tally.stats.rays = points.size();
  PointQueryContext ctx{*store_, *cache_, tally, options.strict};
  OUTCORE_RETURN_IF_ERROR(find_closest_points(ctx, points, answers));
  cache_->release_evicted_pages();
  finish_batch_stats(tally, *cache_, counters_before, start, ticks_start, nullptr);
  if (stats_out != nullptr) *stats_out = tally.stats;
  return Status::Ok();
}

Status QueryEngine::occupancy(std::span<const Vec3f> points, std::span<uint8_t> inside,
                              const QueryOptions& options, QueryStats* stats_out) {
  if (inside.size() != points.size()) return invalid_argument("occupancy flags and points differ in length");
  QueryStats total;
  std::fill(inside.begin(), inside.end(), uint8_t{0});
  // Points whose rays so far met an edge.
  OUTCORE_ASSIGN_OR_RETURN(std::vector<uint32_t> pending,
                           valid_point_ids(points, options.strict, total.invalid_rays));
  std::vector<uint8_t> odd_votes(points.size(), 0);
  std::vector<Ray> rays;
  std::vector<uint32_t> counts;
  std::vector<RayHitRecord> records;
  for (int round = 0; round < kOccupancyDirections && !pending.empty(); ++round) {
    const Vec3f direction = occupancy_direction(round);
    rays.assign(pending.size(), Ray{});
    for (std::size_t k = 0; k < pending.size(); ++k) rays[k] = {points[pending[k]], direction, 0.0f};
    counts.assign(pending.size(), 0);
    QueryStats round_stats;
    OUTCORE_RETURN_IF_ERROR(all_hits(rays, counts, &records, options, &round_stats));
    total.add(round_stats);
    std::vector<uint32_t> undecided;
    std::size_t at = 0;
    for (std::size_t k = 0; k < pending.size(); ++k) {
      const std::size_t begin = at;
      while (at < records.size() && records[at].ray == k) ++at;
      const ParityVerdict verdict = parity_of({records.data() + begin, at - begin});
      const uint32_t i = pending[k];
      odd_votes[i] += verdict.odd;
      if (verdict.trusted) {
        inside[i] = verdict.odd;
      } else if (round + 1 < kOccupancyDirections) {
        undecided.push_back(i);
      } else {
        inside[i] = 2 * odd_votes[i] > kOccupancyDirections;  // every direction met an edge
      }
    }
    pending = std::move(undecided);
  }
  total.rays = points.size();
  total.rays_hit = 0;
  for (const uint8_t flag : inside) total.rays_hit += flag;
  if (stats_out != nullptr) *stats_out = total;
  return Status::Ok();
}

namespace {

// The dynamic layer after the static scene, merged into its answers.
template <QueryKind kKind>
Status trace_dynamic(const DynamicSnapshot& dynamic, std::span<const Ray> rays, Hit* hits, uint8_t* occluded,
                     QueryStats& stats) {
  stats.dynamic_version = dynamic.version;
  stats.dynamic_instances = dynamic.instances.size();
  if (dynamic.instances.empty()) return Status::Ok();
  if constexpr (kKind == QueryKind::kAllHits) return static_scene_only(dynamic, "count and list queries");
  const auto start = Clock::now();
  const uint64_t newly_hit = kKind == QueryKind::kClosestHit
                                 ? dynamic.intersect(rays, {hits, rays.size()})
                                 : dynamic.occluded(rays, {occluded, rays.size()});
  stats.rays_hit += newly_hit;
  stats.rays_hit_only_dynamic += newly_hit;
  stats.seconds_dynamic += seconds_since(start);
  return Status::Ok();
}

template <QueryKind kKind>
Status run_strategy(BatchStrategy strategy, StrategyContext<kKind>& ctx) {
  switch (strategy) {
    case BatchStrategy::kSequential: return run_sequential(ctx);
    case BatchStrategy::kResidentSet: return run_resident_set(ctx);
    case BatchStrategy::kInCacheSweep: return run_in_cache_sweep(ctx);
    case BatchStrategy::kQueued: return run_queued(ctx);
  }
  return internal_error("unknown batch strategy");
}

}  // namespace

std::shared_ptr<const UpperWalks> QueryEngine::walks_for_part(std::span<const uint32_t> only_bricks) const {
  std::vector<uint8_t> in_part(store_->brick_count(), 0);
  for (const uint32_t b : only_bricks) in_part[b] = 1;
  std::lock_guard lock(part_walks_mutex_);
  if (part_walks_ == nullptr || part_walks_key_ != in_part) {
    part_walks_ = std::make_shared<const UpperWalks>(upper_walks_->restricted_to(in_part));
    part_walks_key_ = std::move(in_part);
  }
  return part_walks_;
}

template <QueryKind kKind>
Status QueryEngine::run(std::span<const Ray> rays, Answers answers, const QueryOptions& options,
                        QueryStats* stats_out) {
  Hit* const hits = answers.hits;
  uint8_t* const occluded = answers.occluded;
  const auto start = Clock::now();
  const uint64_t ticks_start = ticks();
  const uint32_t brick_count = store_->brick_count();
  for (const uint32_t b : options.only_bricks) {
    if (b >= brick_count)
      return invalid_argument("only_bricks: brick " + std::to_string(b) + " is not in the scene (its " +
                              std::to_string(brick_count) + " bricks have ids below " +
                              std::to_string(brick_count) + ")");
  }
  const std::shared_ptr<const UpperWalks> part_walks =
      options.only_bricks.empty() ? nullptr : walks_for_part(options.only_bricks);
  const UpperWalks& upper_walks = part_walks != nullptr ? *part_walks : *upper_walks_;
  ProxyGate gate(proxies_.get(), cache_->builder().hit_rounding_scale(), bounds_.get());
  if (proxies_ != nullptr && options.reorder) {
    // Nothing is ever evicted when the budget holds the scene: a brick is
    // built at most once, so its queue is tested when it is to be built
    // rather than each ray on arrival, and no view of what is resident is
    // needed. Otherwise rays are tested on arrival, at bricks not resident.
    if (cache_fits_scene_) {
      gate.defer_to_builds();
    } else {
      gate.track_residency(brick_count, cache_->resident_bricks());
    }
  }
  const CacheCounters counters_before = cache_->counters();
  const std::size_t n = rays.size();
  BatchTally tally;
  tally.stats.rays = n;

  std::shared_ptr<const DynamicSnapshot> dynamic = options.dynamic_snapshot;
  if (dynamic == nullptr) {
    OUTCORE_ASSIGN_OR_RETURN(dynamic, options.dynamic_version == kLatestDynamicVersion
                                          ? dynamic_.latest()
                                          : dynamic_.at(options.dynamic_version));
  }
  const ReusePool<BatchScratch>::Lease scratch = scratch_pool_.take();
  const uint32_t resident_bricks = cache_->counters().resident_bricks;
  const BatchPlan plan =
      plan_batch(options, {.rays = n,
                           .brick_count = brick_count,
                           .resident_bricks = resident_bricks,
                           .cache_fits_scene = cache_fits_scene_,
                           .resident_set_max_bricks = cache_->builder().resident_set_max_bricks()});
  // The chunked strategies validate rays in their own chunks, and the queues
  // in the chunks of their first upper pass (one pass less over the rays'
  // memory), except in strict mode, where a bad ray must stop the batch
  // before anything is traced. The chunked strategies keep their own per-ray
  // state: no flags or progress records for the whole batch.
  const bool validate_apart = !options.reorder || options.strict;
  const bool chunked =
      plan.strategy == BatchStrategy::kInCacheSweep || plan.strategy == BatchStrategy::kResidentSet;
  if ((!chunked || validate_apart) && scratch->valid.size() < n) scratch->valid.resize(n);
  if (!chunked && scratch->progress.size() < n) scratch->progress.resize(n);
  const QueryBatch<kKind> batch{
      rays, hits, occluded, scratch->valid.data(), validate_apart, answers.hit_counts, answers.collector};
  if (validate_apart)
    OUTCORE_RETURN_IF_ERROR(validate_batch(batch, options.strict, tally.stats.invalid_rays));

  // A builder that chooses per brick wants the rays ahead of the bricks it
  // is about to build: not counted (shared atomics) when every brick is resident.
  const bool builds_ahead = cache_->builder().uses_demand() && resident_bricks < brick_count;
  const bool track_demand = options.reorder && plan.strategy != BatchStrategy::kInCacheSweep &&
                            (cache_->wants_schedule_hint() || builds_ahead);
  BrickDemand demand(track_demand, brick_count);
  // Trace-ahead is possible only when the budget cannot hold the scene.
  const bool ahead_possible = options.reorder && options.trace_ahead && !cache_fits_scene_;
  if (ahead_possible && scratch->ahead_state.size() < n) scratch->ahead_state.resize(n);
  scratch->ahead_hits.clear();
  const RayWalk<kKind> walk{batch,
                            upper_walks,
                            options.avx_upper && cpu_has_avx(),
                            gate,
                            demand,
                            ahead_possible ? scratch->ahead_state.data() : nullptr,
                            scratch->ahead_hits};
  StrategyContext<kKind> ctx{
      batch,           walk, *cache_, *store_, gate, demand, *scratch, options, bricks_budget_holds_,
      counters_before, tally};
  OUTCORE_RETURN_IF_ERROR(run_strategy(plan.strategy, ctx));
  OUTCORE_RETURN_IF_ERROR(trace_dynamic<kKind>(*dynamic, rays, hits, occluded, tally.stats));

  // The batch's evicted bricks hold no pages past its end.
  cache_->release_evicted_pages();
  finish_batch_stats(tally, *cache_, counters_before, start, ticks_start, proxies_.get());
  if (stats_out != nullptr) *stats_out = tally.stats;
  return Status::Ok();
}

template Status QueryEngine::run<QueryKind::kClosestHit>(std::span<const Ray>, Answers, const QueryOptions&,
                                                         QueryStats*);
template Status QueryEngine::run<QueryKind::kAnyHit>(std::span<const Ray>, Answers, const QueryOptions&,
                                                     QueryStats*);
template Status QueryEngine::run<QueryKind::kAllHits>(std::span<const Ray>, Answers, const QueryOptions&,
                                                      QueryStats*);

}  // namespace outcore
