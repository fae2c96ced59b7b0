// QueryEngine: answers closest-hit and any-hit queries for ray batches against
// an opened scene store. The store's manifest and fixed upper hierarchy stay
// resident; brick structures are built on first need into a byte-budgeted
// BrickCache (core/cache). With reordering (the default; Pharr et al. 1997) the
// rays of a batch queue at bricks, bricks are processed one at a time —
// resident ones first, then the longest queue — and each ray advances brick by
// brick in its own front-to-back order (upper_traversal.h), finishing once its
// hit is nearer than the next brick's entry (closest hit) or at its first hit
// (any hit). Each ray therefore visits the same bricks in the same order
// whatever the batch, budget, policy or thread count, so answers are bitwise
// identical across all of them. When nothing waiting is resident, several
// bricks are built at once (one per thread). Under a budget smaller than the
// scene, a brick being built is also traced by the rays that reach it later
// ("trace-ahead"); each keeps the outcome until its own turn there, so its
// visits and answer are unchanged and the brick need not be built again for
// it (docs/DESIGN.md). When a scene of a few bricks is wholly resident under a
// budget that holds it, threads instead take chunks of consecutive rays
// through all their bricks ("in-cache sweep"): same visits, same answers.
//
// Brick proxies (core/proxy, on by default): before a ray is queued at a
// brick, its segment is marched through the brick's resident occupancy grid;
// a brick it cannot hit is skipped without being loaded or traced. Proxies
// are conservative, so answers are bitwise the same with them off.
//
// Invalid rays (NaN/Inf components, components beyond +-1.844e18, zero
// direction, tnear < 0 or not finite, tnear > tfar, NaN tfar) are answered
// as misses and counted; with strict they are an INVALID_ARGUMENT naming the
// first bad ray.
//
// Cancellation: once cancel_requested() (core/util/cancellation.h) is true, a
// batch stops at its next brick (at its next ray with reordering off) and
// returns CANCELLED, its answers incomplete; the server cancels its in-flight
// batches so when its drain after SIGTERM runs out.
//
// Thread-safety: intersect() and occluded() may be called concurrently from
// several threads; concurrent batches share the cache (and its budget).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/cache/brick_cache.h"
#include "core/dynamic/dynamic_scene.h"
#include "core/proxy/proxy_builder.h"
#include "core/proxy/proxy_set.h"
#include "core/query/query_stats.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_problem.h"
#include "core/ray/ray_types.h"
#include "core/store/scene_store.h"
#include "core/upper/brick_bounds.h"
#include "core/util/reuse_pool.h"

namespace outcore {

struct AllHitsCollector;  // query_batch.h
struct BatchScratch;      // batch_scratch.h
struct UpperWalks;        // upper_walks.h

struct EngineOptions {
  // Hard budget for built bricks, in bytes.
  uint64_t cache_bytes = uint64_t{1024} << 20;
  std::string eviction_policy = "lru";
  std::string brick_accel = kDefaultBrickAccel;
  BrickAccelOptions accel_options;
  // The bound tested before a brick beyond the upper hierarchy's box:
  // "aabb" (none), "sphere" or "obb" (core/upper/brick_bounds.h).
  std::string brick_bounds = kDefaultBrickBounds;
  // The dynamic layer's structure over its instances: "bvh" (an 8-wide BVH)
  // or "bkd" (the seed's B-KD tree); answers are the same.
  std::string dynamic_top_level = "bvh";
  // When set, the cache records every brick acquisition into it
  // (core/cache/access_trace.h); close it after the engine is destroyed.
  std::shared_ptr<AccessTraceWriter> access_trace;
  // Skip bricks a ray cannot hit by their occupancy proxies (read from the
  // store's proxies.bin, or built on open and cached there).
  bool proxies = true;
  ProxyBuildConfig proxy_config;
  // When set, built bricks are saved to this directory and later misses load
  // them from it instead of building (core/cache/subtree_tier.h); only for
  // brick structures that can be serialised (bvh). subtree_max_bytes bounds
  // the files kept there (0: unbounded); subtree_release_batch_bytes batches
  // the release of evicted bricks' pages (SubtreeTierOptions).
  std::string subtree_dir;
  uint64_t subtree_max_bytes = 0;
  uint64_t subtree_release_batch_bytes = kDefaultReleaseBatchBytes;
};

struct QueryOptions {
  // Queue rays at bricks and process brick by brick; false runs the rays one
  // by one in input order (for comparison).
  bool reorder = true;
  // Invalid rays are an error instead of counted misses.
  bool strict = false;
  // Under a budget that cannot hold the scene, a brick being built is also
  // traced by the rays that will reach it later, so that it need not be
  // built again for them (trace_ahead.h). Answers are the same either way.
  bool trace_ahead = true;
  // When every brick is resident and the budget holds the scene, threads
  // take chunks of consecutive rays through all their bricks instead of
  // queueing the batch at bricks (strategy_in_cache_sweep.cpp). Answers are the same
  // either way; false forces the queues (for comparison).
  bool in_cache_sweep = true;
  // On CPUs with AVX, the upper hierarchy is walked 8 boxes at a time for
  // one ray (core/upper/upper_wide8_traversal.h), and in the first pass 8
  // rays at a time where 8 consecutive rays share a direction octant
  // (upper_packet_traversal.h); false walks it 4-wide with SSE (for
  // comparison). Answers are the same either way; only the count of upper
  // boxes tested differs.
  bool avx_upper = true;
  // When every brick is resident, the budget holds the scene, the brick
  // structure offers a resident set (core/accel/resident_brick_set.h) and
  // there are at most 16 bricks, a batch of at least brick_set_min_rays rays
  // goes through one structure over every brick: one call per chunk of rays
  // instead of the upper walk and a call per brick visit. Answers are the
  // same either way; false walks the upper hierarchy (for comparison, and
  // for the per-brick statistics, which the set cannot give). Smaller
  // batches take the sweep: the set is made per batch.
  bool brick_set = true;
  std::size_t brick_set_min_rays = 16384;
  // The dynamic layer's version the batch sees (DynamicScene::at); the
  // latest when the batch starts by default.
  uint64_t dynamic_version = kLatestDynamicVersion;
  // A version already taken (a call traced in parts keeps one version for
  // all of them, however many changes are made meanwhile); wins over
  // dynamic_version when set.
  std::shared_ptr<const DynamicSnapshot> dynamic_snapshot;
  // When not empty, the batch traces only these bricks (ids below
  // brick_count; any order, repeats allowed; INVALID_ARGUMENT naming the
  // first id out of range): each ray's answer is its nearest hit (closest
  // hit) or its occlusion (any hit) among their triangles; the upper walks
  // are restricted to the part (core/upper/upper_part.h), so the other
  // bricks and the subtrees holding none of the part are never traversed,
  // loaded or built. A replica that owns part of the scene answers
  // for its part; the nearest of the parts' hits under the tie rule
  // (hit_is_better) is bitwise the whole scene's answer, and a ray is
  // occluded when any part says so. The dynamic layer is traced whole.
  std::vector<uint32_t> only_bricks;
};

class QueryEngine {
 public:
  static Expected<std::unique_ptr<QueryEngine>> open(const std::string& store_directory,
                                                     const EngineOptions& options);
  static Expected<std::unique_ptr<QueryEngine>> create(std::shared_ptr<const SceneStore> store,
                                                       const EngineOptions& options);

  // hits.size() must equal rays.size().
  Status intersect(std::span<const Ray> rays, std::span<Hit> hits, const QueryOptions& options,
                   QueryStats* stats = nullptr);
  // occluded[i] = 1 when ray i hits anything in [tnear, tfar].
  Status occluded(std::span<const Ray> rays, std::span<uint8_t> occluded, const QueryOptions& options,
                  QueryStats* stats = nullptr);

  // Every hit of every ray (Open3D's count_intersections and
  // list_intersections): counts[i] hits on ray i in (tnear, tfar], each
  // triangle once; with `records`, every (ray, hit) too, sorted by ray, then
  // t, then (geometry_id, primitive_id). counts.size() must equal
  // rays.size(). The dynamic layer is not seen: FAILED_PRECONDITION when it
  // holds instances.
  Status all_hits(std::span<const Ray> rays, std::span<uint32_t> counts, std::vector<RayHitRecord>* records,
                  const QueryOptions& options, QueryStats* stats = nullptr);
  // The closest point of the scene to each point (point_queries.h);
  // answers.size() must equal points.size(). Like all_hits, the static
  // scene only: FAILED_PRECONDITION while the dynamic layer holds instances.
  Status closest_points(std::span<const Vec3f> points, std::span<ClosestPoint> answers,
                        const QueryOptions& options, QueryStats* stats = nullptr);
  // Whether each point is inside the closed surfaces, by the parity of
  // every-hit counts along rays from it (point_queries.h).
  Status occupancy(std::span<const Vec3f> points, std::span<uint8_t> inside, const QueryOptions& options,
                   QueryStats* stats = nullptr);

  const SceneStore& store() const { return *store_; }
  const BrickCache& cache() const { return *cache_; }
  // nullptr when proxies are off.
  const ProxySet* proxies() const { return proxies_.get(); }
  const BrickBounds& brick_bounds() const { return *bounds_; }
  // How the proxies were obtained (loaded from proxies.bin or built).
  const ProxyOpenReport& proxy_report() const { return proxy_report_; }
  // The brick structure's options in effect (the user's).
  const BrickAccelOptions& accel_options() const { return accel_options_; }
  // Whether the budget holds every brick at once (by their reservations).
  bool cache_fits_scene() const { return cache_fits_scene_; }
  // The dynamic layer (core/dynamic/dynamic_scene.h): meshes and instances
  // added at run time beside the static store; every batch traces the
  // static scene, then the version of the layer it names, and keeps the
  // nearer hit under the same tie rule. Dynamic geometry ids continue after
  // the store's inputs.
  DynamicScene& dynamic() { return dynamic_; }
  const DynamicScene& dynamic() const { return dynamic_; }

  ~QueryEngine();

 private:
  QueryEngine(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickCache> cache,
              std::unique_ptr<const ProxySet> proxies, ProxyOpenReport proxy_report, bool cache_fits_scene,
              uint64_t bricks_budget_holds, DynamicTopLevel dynamic_top_level);

  // Plans the batch (batch_planner.h) and runs its strategy (strategy.h).
  struct Answers {
    Hit* hits = nullptr;
    uint8_t* occluded = nullptr;
    uint32_t* hit_counts = nullptr;
    AllHitsCollector* collector = nullptr;
  };
  template <QueryKind kKind>
  Status run(std::span<const Ray> rays, Answers answers, const QueryOptions& options, QueryStats* stats);

  std::shared_ptr<const SceneStore> store_;
  std::unique_ptr<BrickCache> cache_;
  std::unique_ptr<const ProxySet> proxies_;
  std::unique_ptr<const BrickBounds> bounds_;
  ProxyOpenReport proxy_report_;
  bool cache_fits_scene_;
  uint64_t bricks_budget_holds_;  // the budget over the average brick reservation
  BrickAccelOptions accel_options_;
  // The upper hierarchy in the forms the walks use, made once on open.
  std::unique_ptr<const UpperWalks> upper_walks_;
  // The walks of the last part of the scene a batch traced
  // (QueryOptions::only_bricks; a replica traces the same part batch after
  // batch), made on the first batch that names it.
  std::shared_ptr<const UpperWalks> walks_for_part(std::span<const uint32_t> only_bricks) const;
  mutable std::mutex part_walks_mutex_;
  mutable std::vector<uint8_t> part_walks_key_;  // in_part by brick id
  mutable std::shared_ptr<const UpperWalks> part_walks_;
  // Per-batch working memory kept for the next batch, so that warm batches
  // neither allocate nor page-fault it.
  ReusePool<BatchScratch> scratch_pool_;
  DynamicScene dynamic_;
};

}  // namespace outcore
