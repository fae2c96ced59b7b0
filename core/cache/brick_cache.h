// BrickCache: built bricks (BrickAccel) held under a hard byte budget.
//
// - Lazy and single-flight: the first acquire() of a brick loads it from the
//   store (checksum verified) and builds it; concurrent acquirers of the same
//   brick wait for that one build (state absent -> building -> ready).
// - Pinning: acquire() returns a PinnedBrick; a pinned brick is never evicted.
//   Release pins promptly: a caller holding a pin must not wait on the cache.
// - Budget: before building, the cache reserves the builder's upper bound
//   (BrickBuilder::reserve_bytes), evicting unpinned bricks by policy to make
//   room, waiting for unpins if everything else is pinned; after the build the
//   reservation shrinks to the brick's true bytes. Accounted bytes therefore
//   never exceed the budget. A brick whose bound exceeds the whole budget is
//   RESOURCE_EXHAUSTED naming it. Evicted bricks stay accounted until they are
//   destroyed (outside the lock), so accounted bytes bound the cache's memory.
// - Errors: a failed load or build (DATA_LOSS from a corrupted brick, a builder
//   error) releases the reservation and leaves the brick absent; the cache
//   stays usable. Acquirers that were waiting for that build wake and retry it
//   themselves, so each gets its own outcome (a corrupted brick fails for every
//   one of them; a transient error may succeed on retry). A brick id beyond the
//   store is OUT_OF_RANGE (as in SceneStore::load_brick).
// - Subtree tier (optional, enable_subtree_tier; subtree_tier.h): on a miss
//   the brick is loaded from the tier's directory when it holds a valid file,
//   else loaded from the store, built and saved to the tier, by the thread
//   that missed (outside the lock; acquirers of the same brick wait for the
//   save too). Either way the cache keeps the tier's copy of the file, read
//   in place (a mapping of its own, not the heap; eviction releases it),
//   unless the save failed. A loaded brick is accounted exactly as a built
//   one (the serialiser guarantees the same memory_bytes(), which covers
//   the copy).
// - Counters: hits + misses counts successful acquisitions; failed ones are in
//   neither. builds, bytes_built and build_seconds count successful builds;
//   misses served by the tier are in subtree.loads instead (so, once idle,
//   misses = builds + subtree.loads + acquisitions that waited).
// - Access trace (optional, set_access_trace): every successful acquisition is
//   recorded (access_trace.h; a miss served by the tier as a "load") into a
//   buffer under the lock and handed to the writer in chunks outside it; the
//   destructor and flush_access_trace() hand over the rest.
//
// Thread-safety: all member functions may be called from any thread. One mutex
// guards the table; it is taken per brick acquisition, never per ray, and is
// not held while loading or building.
#pragma once

#include <array>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/cache/access_trace.h"
#include "core/cache/eviction_policy.h"
#include "core/cache/subtree_tier.h"
#include "core/store/scene_store.h"

namespace outcore {

struct CacheCounters {
  uint64_t hits = 0;    // acquisitions of a ready brick
  uint64_t misses = 0;  // acquisitions that built (or waited for a build)
  uint64_t builds = 0;  // brick builds performed
  uint64_t evictions = 0;
  uint64_t bytes_built = 0;
  double build_seconds = 0;  // load + build, summed over builds
  uint64_t resident_bytes = 0;
  uint64_t peak_resident_bytes = 0;  // accounted (reservations included)
  uint32_t resident_bricks = 0;
  // Builds whose true bytes exceeded BrickBuilder::reserve_bytes (a builder
  // bug; each is logged). Only these can push accounted bytes past the budget.
  uint64_t reservation_overruns = 0;
  // Builds by structure (brick_accel_names() order; with auto, the chosen
  // candidate), and bricks rebuilt as another structure because their rays
  // paid for it (BrickBuilder::worth_rebuilding; each is also a build).
  std::array<uint64_t, kMaxBrickStructures> builds_by_structure{};
  uint64_t rebuilds = 0;
  // The subtree tier's own counters (all zero without a tier): loads, writes,
  // rejections by reason, bytes and seconds.
  SubtreeTierCounters subtree;
};

class BrickCache;

// A pin on a ready brick; unpins on destruction. Must not outlive its cache.
class PinnedBrick {
 public:
  PinnedBrick() = default;
  PinnedBrick(PinnedBrick&& other) noexcept { *this = std::move(other); }
  PinnedBrick& operator=(PinnedBrick&& other) noexcept;
  ~PinnedBrick() { release(); }
  PinnedBrick(const PinnedBrick&) = delete;
  PinnedBrick& operator=(const PinnedBrick&) = delete;

  const BrickAccel& accel() const { return *accel_; }
  bool pinned() const { return accel_ != nullptr; }
  uint32_t brick_id() const { return brick_; }
  // True when this acquisition found the brick ready (no build, no wait).
  bool was_hit() const { return was_hit_; }
  void release();

 private:
  friend class BrickCache;
  BrickCache* cache_ = nullptr;
  const BrickAccel* accel_ = nullptr;
  uint32_t brick_ = 0;
  bool was_hit_ = false;
};

class BrickCache {
 public:
  BrickCache(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickBuilder> builder,
             std::unique_ptr<EvictionPolicy> policy, uint64_t budget_bytes);
  ~BrickCache();
  BrickCache(const BrickCache&) = delete;
  BrickCache& operator=(const BrickCache&) = delete;

  // `rays`: how many rays the caller will trace in the brick with this pin
  // (0: not known). The cache sums them per brick (kept across evictions)
  // as the brick's expected use: a builder that chooses per brick
  // (BuildDemand) builds for it, and a ready, unpinned brick its builder
  // finds worth rebuilding for it is built again (counted in rebuilds and
  // builds, not in evictions).
  // `rays_ahead`: rays of the caller's batch that have the brick ahead of
  // them, these `rays` included (0: not known): the batch's use of the brick
  // is expected to be at least that.
  Expected<PinnedBrick> acquire(uint32_t brick_id, uint64_t rays = 0, uint64_t rays_ahead = 0);
  // Adds rays traced in bricks under pins acquired without a count
  // (rays_by_brick[b] for brick b; one lock for all) to their expected use.
  void add_rays_served(std::span<const uint64_t> rays_by_brick);
  bool is_resident(uint32_t brick_id) const;
  CacheCounters counters() const;
  uint64_t budget_bytes() const { return budget_bytes_; }
  const BrickBuilder& builder() const { return *builder_; }
  const EvictionPolicy& policy() const { return *policy_; }

  // Keeps built bricks in a subtree tier (see above). Call before the first
  // acquire. FAILED_PRECONDITION when the builder's structure cannot be
  // serialised (BrickBuilder::serializer() is null); the tier's open errors.
  Status enable_subtree_tier(const SubtreeTierOptions& options);
  // nullptr without a tier.
  const SubtreeTier* subtree_tier() const { return tier_.get(); }
  // Releases the pages of evicted tier-loaded bricks still queued for release
  // (SubtreeTier::release_pending_pages); nothing without a tier.
  void release_evicted_pages();

  // Records every later acquisition into `trace` (nullptr stops recording).
  // Set it before the first acquire so the trace starts from an empty cache.
  void set_access_trace(std::shared_ptr<AccessTraceWriter> trace);
  // Hands the buffered records to the writer now (they are written in order).
  void flush_access_trace();
  // Passes the bricks the caller will request next, soonest first, to the
  // policy (EvictionPolicy::on_schedule_hint).
  void hint_schedule(std::span<const uint32_t> upcoming);
  // Whether the policy uses hints (fixed at construction).
  bool wants_schedule_hint() const { return policy_->wants_schedule_hint(); }
  // The ids of the bricks ready now, ascending (O(bricks) under the lock; for
  // building hints, once per brick build, never per ray).
  std::vector<uint32_t> resident_bricks() const;

 private:
  friend class PinnedBrick;
  enum class State : uint8_t { kAbsent, kBuilding, kReady };
  struct Entry {
    State state = State::kAbsent;
    uint32_t pins = 0;
    uint64_t bytes = 0;        // accounted (a reservation while building)
    uint64_t rays_served = 0;  // the acquisitions' rays, summed over the cache's life
    std::unique_ptr<BrickAccel> accel;
  };

  void unpin(uint32_t brick_id);
  // A pin on a ready brick (the caller has counted it in entry.pins).
  PinnedBrick make_pin(uint32_t brick_id, const BrickAccel* accel, bool was_hit);
  // Under the lock: a build's figures (not a tier load's).
  void count_build(const BrickAccel& accel, uint64_t bytes, double seconds);
  // Under the lock: takes a ready, unpinned brick out to be built again
  // (the accel into `victims`, its bytes returned, still accounted).
  uint64_t take_for_rebuild(uint32_t brick_id, std::vector<std::unique_ptr<BrickAccel>>& victims);
  // Evicts unpinned ready bricks until `bytes` more fit, waiting for unpins and
  // builds when everything left is pinned or building; false if it cannot
  // (`bytes` is more than the whole budget).
  bool make_room(uint64_t bytes, std::unique_lock<std::mutex>& lock);
  // Moves unpinned ready bricks chosen by the policy into `victims` until
  // `bytes` more would fit once they are gone, or none is left; returns their
  // bytes, which stay accounted until release_victims().
  uint64_t evict_unpinned(uint64_t bytes, std::vector<std::unique_ptr<BrickAccel>>& victims);
  // Destroys `victims` outside the lock (an Embree scene's destructor takes
  // Embree's own mutex), then stops accounting their `bytes` and notifies.
  void release_victims(std::vector<std::unique_ptr<BrickAccel>>& victims, uint64_t bytes,
                       std::unique_lock<std::mutex>& lock);
  void account(int64_t delta);
  // Under the lock: appends a record; returns a full chunk to hand to the
  // writer once the lock is released (empty otherwise).
  std::vector<AccessRecord> record_access(uint32_t brick, uint64_t bytes, uint64_t reserved, double seconds,
                                          AccessOutcome outcome, uint64_t rays);
  void hand_over(std::vector<AccessRecord> chunk);
  Status too_large(uint32_t brick_id, uint64_t reservation) const;
  SubtreeKey subtree_key(uint32_t brick_id) const;

  std::shared_ptr<const SceneStore> store_;
  std::unique_ptr<BrickBuilder> builder_;
  std::unique_ptr<EvictionPolicy> policy_;
  const uint64_t budget_bytes_;
  std::unique_ptr<SubtreeTier> tier_;  // set before the first acquire, then fixed

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<Entry> entries_;
  CacheCounters counters_;
  std::shared_ptr<AccessTraceWriter> trace_;
  std::vector<AccessRecord> trace_buffer_;
  uint64_t trace_seq_ = 0;
  // The last schedule hint, recorded with the next acquisition (traced only).
  bool has_pending_hint_ = false;
  std::vector<uint32_t> pending_hint_;
};

}  // namespace outcore
