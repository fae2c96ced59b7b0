#include "core/cache/brick_cache.h"

#include "core/cache/cache_budget.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cstdio>
#include <exception>
#include <new>
#include <string>
#include <utility>

namespace outcore {
namespace {

// Loads brick `key.brick_id` from the tier when there is one and it holds
// the brick (*loaded = true), else from the store (checksum verified) and
// builds it. Every failure, including an exception from the builder, comes
// back as a Status naming the brick, so the caller can always undo its
// reservation.
// A tier file whose structure the builder would rebuild for `demand` is not
// used (it is replaced by the new build).
Expected<std::unique_ptr<BrickAccel>> load_and_build(const SceneStore& store, const BrickBuilder& builder,
                                                     SubtreeTier* tier, const SubtreeKey& key,
                                                     const BuildDemand& demand, bool& loaded) {
  const uint32_t id = key.brick_id;
  const std::string brick = "brick " + std::to_string(id);
  try {
    if (tier != nullptr) {
      std::unique_ptr<BrickAccel> accel = tier->load(key);
      loaded = accel != nullptr && !builder.worth_rebuilding(*accel, demand);
      if (loaded) return accel;
    }
    BrickData data;
    OUTCORE_RETURN_IF_ERROR(store.load_brick(id, data));  // names the brick
    Expected<std::unique_ptr<BrickAccel>> built = builder.build_for(std::move(data), demand);
    if (!built.ok())
      return built.status().with_context("building " + brick + " with '" + builder.name() + "'");
    if (*built == nullptr)
      return internal_error("builder '" + builder.name() + "' returned nothing for " + brick);
    if (tier != nullptr) {
      // Keep the saved file (mapped) rather than the built copy: see
      // subtree_tier.h. The tier is a cache: a failure to save costs only the
      // saving, never the build.
      try {
        if (std::unique_ptr<BrickAccel> saved = tier->store(key, **built)) return saved;
      } catch (const std::exception& e) {
        spdlog::warn("subtree tier: saving {} threw: {}", brick, e.what());
      }
    }
    return built;
  } catch (const std::bad_alloc&) {
    return resource_exhausted("out of memory while loading or building " + brick);
  } catch (const std::exception& e) {
    return internal_error("loading or building " + brick + " threw: " + e.what());
  }
}

}  // namespace

PinnedBrick& PinnedBrick::operator=(PinnedBrick&& other) noexcept {
  if (this != &other) {
    release();
    cache_ = std::exchange(other.cache_, nullptr);
    accel_ = std::exchange(other.accel_, nullptr);
    brick_ = std::exchange(other.brick_, 0);
    was_hit_ = std::exchange(other.was_hit_, false);
  }
  return *this;
}

void PinnedBrick::release() {
  if (cache_ == nullptr) return;
  BrickCache* cache = std::exchange(cache_, nullptr);
  accel_ = nullptr;
  cache->unpin(brick_);
}

BrickCache::BrickCache(std::shared_ptr<const SceneStore> store, std::unique_ptr<BrickBuilder> builder,
                       std::unique_ptr<EvictionPolicy> policy, uint64_t budget_bytes)
    : store_(std::move(store)),
      builder_(std::move(builder)),
      policy_(std::move(policy)),
      budget_bytes_(budget_bytes),
      entries_(store_ ? store_->brick_count() : 0) {
  assert(store_ && builder_ && policy_);
  policy_->set_budget(budget_bytes_);
}

BrickCache::~BrickCache() {
  flush_access_trace();
#ifndef NDEBUG
  for (const Entry& entry : entries_) {
    assert(entry.pins == 0 && "a PinnedBrick outlived its BrickCache");
    assert(entry.state != State::kBuilding);
  }
#endif
}

Status BrickCache::too_large(uint32_t brick_id, uint64_t reservation) const {
  return resource_exhausted("brick " + std::to_string(brick_id) + " needs up to " +
                            describe_bytes(reservation) + " to build, more than the cache budget of " +
                            describe_bytes(budget_bytes_) +
                            "; raise the budget or repack with smaller bricks");
}

PinnedBrick BrickCache::make_pin(uint32_t brick_id, const BrickAccel* accel, bool was_hit) {
  PinnedBrick pin;
  pin.cache_ = this;
  pin.accel_ = accel;
  pin.brick_ = brick_id;
  pin.was_hit_ = was_hit;
  return pin;
}

void BrickCache::count_build(const BrickAccel& accel, uint64_t bytes, double seconds) {
  ++counters_.builds;
  const std::size_t structure = brick_structure_index(builder_->structure_of(accel));
  if (structure < kMaxBrickStructures) ++counters_.builds_by_structure[structure];
  counters_.bytes_built += bytes;
  counters_.build_seconds += seconds;
}

Expected<PinnedBrick> BrickCache::acquire(uint32_t brick_id, uint64_t rays, uint64_t rays_ahead) {
  if (brick_id >= entries_.size()) {
    // The same code and words as SceneStore::load_brick for the same mistake.
    return out_of_range("brick " + std::to_string(brick_id) + " does not exist (the scene has " +
                        std::to_string(entries_.size()) + " bricks)");
  }
  const uint32_t triangles = store_->manifest().bricks[brick_id].triangle_count;
  const uint64_t reservation = builder_->reserve_bytes(triangles);
  // entries_ is never resized, so this reference stays valid across unlocks.
  Entry& entry = entries_[brick_id];

  std::unique_lock lock(mutex_);
  entry.rays_served += rays;
  // The batch's rays still on their way to the brick count for this build only.
  const uint64_t on_their_way = rays_ahead > rays ? rays_ahead - rays : 0;
  BuildDemand demand{rays, entry.rays_served + on_their_way};
  bool waited = false;
  while (entry.state != State::kAbsent) {
    if (entry.state == State::kReady && entry.rays_served > 0 && entry.pins == 0 &&
        builder_->worth_rebuilding(*entry.accel, demand)) {
      std::vector<std::unique_ptr<BrickAccel>> victims;
      const uint64_t freed = take_for_rebuild(brick_id, victims);
      release_victims(victims, freed, lock);
      continue;  // absent now, unless another thread began building it
    }
    if (entry.state == State::kReady) {
      ++entry.pins;
      policy_->on_access(brick_id);
      ++(waited ? counters_.misses : counters_.hits);
      PinnedBrick pin = make_pin(brick_id, entry.accel.get(), !waited);
      if (trace_) {
        auto chunk = record_access(brick_id, entry.bytes, reservation, 0.0,
                                   waited ? AccessOutcome::kWait : AccessOutcome::kHit, rays);
        lock.unlock();
        hand_over(std::move(chunk));
      }
      return pin;
    }
    // Building (single flight): wait for that build. If it fails, the brick is
    // absent again and this thread retries the build itself below.
    waited = true;
    changed_.wait(lock);
  }

  // Absent: this thread builds it. Other acquirers of the brick wait from here
  // on, including while this thread waits for room.
  if (reservation > budget_bytes_) return too_large(brick_id, reservation);
  entry.state = State::kBuilding;
  if (!make_room(reservation, lock)) {
    entry.state = State::kAbsent;
    lock.unlock();
    changed_.notify_all();
    return too_large(brick_id, reservation);
  }
  entry.bytes = reservation;
  account(static_cast<int64_t>(reservation));
  demand.rays_expected = entry.rays_served + on_their_way;
  lock.unlock();

  // Load from the tier, or load and build, outside the lock.
  const auto start = std::chrono::steady_clock::now();
  const SubtreeKey key = subtree_key(brick_id);
  bool loaded = false;
  Expected<std::unique_ptr<BrickAccel>> built =
      load_and_build(*store_, *builder_, tier_.get(), key, demand, loaded);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  if (!built.ok()) {
    lock.lock();
    account(-static_cast<int64_t>(reservation));
    entry.bytes = 0;
    entry.state = State::kAbsent;
    lock.unlock();
    changed_.notify_all();
    return built.status();
  }

  std::unique_ptr<BrickAccel> accel = std::move(built).value();
  const uint64_t bytes = accel->memory_bytes();
  lock.lock();
  bool overran = false;
  if (bytes > reservation) {
    // A builder bug: its bound was too small. Keep the accounting honest (true
    // bytes), making room for the excess without waiting; if that is not
    // enough, accounted bytes exceed the budget and the counter says so.
    overran = true;
    ++counters_.reservation_overruns;
    std::vector<std::unique_ptr<BrickAccel>> victims;
    const uint64_t freed = evict_unpinned(bytes - reservation, victims);
    if (!victims.empty()) release_victims(victims, freed, lock);
  }
  account(static_cast<int64_t>(bytes) - static_cast<int64_t>(reservation));
  entry.bytes = bytes;
  entry.accel = std::move(accel);
  entry.state = State::kReady;
  entry.pins = 1;
  // A loaded brick's cost is its load: what missing it again costs now.
  policy_->on_insert(brick_id, bytes, seconds);
  ++counters_.misses;
  ++counters_.resident_bricks;
  if (!loaded) count_build(*entry.accel, bytes, seconds);
  PinnedBrick pin = make_pin(brick_id, entry.accel.get(), false);
  const uint64_t resident = counters_.resident_bytes;
  std::vector<AccessRecord> chunk;
  if (trace_) {
    chunk = record_access(brick_id, bytes, reservation, seconds,
                          loaded ? AccessOutcome::kLoad : AccessOutcome::kMiss, rays);
  }
  lock.unlock();
  changed_.notify_all();
  hand_over(std::move(chunk));
  if (overran) {
    spdlog::warn(
        "brick cache: builder '{}' built brick {} ({} triangles) into {} bytes, more than its "
        "reservation of {} bytes; {} bytes now accounted against a budget of {} bytes",
        builder_->name(), brick_id, triangles, bytes, reservation, resident, budget_bytes_);
  }
  return pin;
}

Status BrickCache::enable_subtree_tier(const SubtreeTierOptions& options) {
  const BrickSerializer* serializer = builder_->serializer();
  if (serializer == nullptr) {
    return failed_precondition("brick structure '" + builder_->name() +
                               "' cannot be kept in a subtree tier (it has no serialiser)");
  }
  OUTCORE_ASSIGN_OR_RETURN(tier_, SubtreeTier::open(options, *serializer));
  return Status::Ok();
}

void BrickCache::release_evicted_pages() {
  if (tier_) tier_->release_pending_pages();
}

SubtreeKey BrickCache::subtree_key(uint32_t brick_id) const {
  SubtreeKey key;
  key.brick_id = brick_id;
  if (!tier_) return key;
  const BrickRecord& record = store_->manifest().bricks[brick_id];
  return SubtreeKey{brick_id, record.checksum, record.triangle_count, tier_->serializer().structure_key()};
}

bool BrickCache::make_room(uint64_t bytes, std::unique_lock<std::mutex>& lock) {
  if (bytes > budget_bytes_) return false;
  for (;;) {
    std::vector<std::unique_ptr<BrickAccel>> victims;
    const uint64_t freed = evict_unpinned(bytes, victims);
    if (!victims.empty()) {
      // The lock is dropped while they are destroyed: look again afterwards.
      release_victims(victims, freed, lock);
      continue;
    }
    if (counters_.resident_bytes + bytes <= budget_bytes_) return true;
    // Everything still accounted is pinned, building, or being destroyed by
    // another thread; each of those notifies when it changes. As bytes <= the
    // budget, resident_bytes > 0 here, so there is something to wait for.
    assert(counters_.resident_bytes > 0);
    changed_.wait(lock);
  }
}

uint64_t BrickCache::evict_unpinned(uint64_t bytes, std::vector<std::unique_ptr<BrickAccel>>& victims) {
  const auto evictable = [this](uint32_t brick) {
    return brick < entries_.size() && entries_[brick].state == State::kReady && entries_[brick].pins == 0;
  };
  uint64_t freed = 0;
  while (counters_.resident_bytes - freed + bytes > budget_bytes_) {
    const std::optional<uint32_t> victim = policy_->choose_victim(evictable);
    if (!victim) break;
    if (!evictable(*victim)) {
      assert(false && "eviction policy chose a brick that is not evictable");
      break;
    }
    Entry& entry = entries_[*victim];
    policy_->on_erase(*victim);
    freed += entry.bytes;
    entry.bytes = 0;
    entry.state = State::kAbsent;
    victims.push_back(std::move(entry.accel));
    ++counters_.evictions;
    --counters_.resident_bricks;
  }
  return freed;
}

void BrickCache::release_victims(std::vector<std::unique_ptr<BrickAccel>>& victims, uint64_t bytes,
                                 std::unique_lock<std::mutex>& lock) {
  lock.unlock();
  victims.clear();
  lock.lock();
  account(-static_cast<int64_t>(bytes));
  changed_.notify_all();
}

uint64_t BrickCache::take_for_rebuild(uint32_t brick_id, std::vector<std::unique_ptr<BrickAccel>>& victims) {
  Entry& entry = entries_[brick_id];
  assert(entry.state == State::kReady && entry.pins == 0);
  policy_->on_erase(brick_id);
  const uint64_t bytes = std::exchange(entry.bytes, 0);
  entry.state = State::kAbsent;
  victims.push_back(std::move(entry.accel));
  ++counters_.rebuilds;
  --counters_.resident_bricks;
  return bytes;
}

void BrickCache::unpin(uint32_t brick_id) {
  {
    std::lock_guard lock(mutex_);
    Entry& entry = entries_[brick_id];
    assert(entry.pins > 0);
    if (--entry.pins != 0) return;
  }
  // Now evictable: a thread waiting for room may proceed.
  changed_.notify_all();
}

void BrickCache::account(int64_t delta) {
  assert(delta >= 0 || counters_.resident_bytes >= static_cast<uint64_t>(-delta));
  counters_.resident_bytes = static_cast<uint64_t>(static_cast<int64_t>(counters_.resident_bytes) + delta);
  counters_.peak_resident_bytes = std::max(counters_.peak_resident_bytes, counters_.resident_bytes);
}

void BrickCache::set_access_trace(std::shared_ptr<AccessTraceWriter> trace) {
  flush_access_trace();
  if (trace) trace->set_info(policy_->name(), budget_bytes_, builder_->name(), store_->brick_count());
  std::lock_guard lock(mutex_);
  trace_ = std::move(trace);
  trace_seq_ = 0;
}

std::vector<AccessRecord> BrickCache::record_access(uint32_t brick, uint64_t bytes, uint64_t reserved,
                                                    double seconds, AccessOutcome outcome, uint64_t rays) {
  // Records are handed over in chunks so the writer's lock and the file are
  // touched once per kChunk acquisitions, never under the cache's lock.
  constexpr std::size_t kChunk = 4096;
  if (trace_buffer_.capacity() < kChunk) trace_buffer_.reserve(kChunk);
  AccessRecord record;
  record.seq = trace_seq_++;
  record.brick = brick;
  record.bytes = bytes;
  record.reserved_bytes = reserved;
  record.build_seconds = seconds;
  record.outcome = outcome;
  record.rays = rays;
  const Entry& entry = entries_[brick];
  if (entry.accel) record.structure = builder_->structure_of(*entry.accel);
  if (has_pending_hint_) {
    record.has_hint = true;
    record.hint = std::exchange(pending_hint_, {});
    has_pending_hint_ = false;
  }
  trace_buffer_.push_back(std::move(record));
  if (trace_buffer_.size() < kChunk) return {};
  return std::exchange(trace_buffer_, {});
}

void BrickCache::hand_over(std::vector<AccessRecord> chunk) {
  if (chunk.empty()) return;
  std::shared_ptr<AccessTraceWriter> trace;
  {
    std::lock_guard lock(mutex_);
    trace = trace_;
  }
  if (trace) trace->append(std::move(chunk));
}

void BrickCache::flush_access_trace() {
  std::vector<AccessRecord> chunk;
  std::shared_ptr<AccessTraceWriter> trace;
  {
    std::lock_guard lock(mutex_);
    chunk = std::exchange(trace_buffer_, {});
    trace = trace_;
  }
  if (trace && !chunk.empty()) trace->append(std::move(chunk));
}

void BrickCache::hint_schedule(std::span<const uint32_t> upcoming) {
  std::lock_guard lock(mutex_);
  policy_->on_schedule_hint(upcoming);
  if (trace_) {
    pending_hint_.assign(upcoming.begin(), upcoming.end());
    has_pending_hint_ = true;
  }
}

std::vector<uint32_t> BrickCache::resident_bricks() const {
  std::lock_guard lock(mutex_);
  std::vector<uint32_t> out;
  out.reserve(counters_.resident_bricks);
  for (uint32_t b = 0; b < entries_.size(); ++b) {
    if (entries_[b].state == State::kReady) out.push_back(b);
  }
  return out;
}

void BrickCache::add_rays_served(std::span<const uint64_t> rays_by_brick) {
  std::lock_guard lock(mutex_);
  const std::size_t bricks = std::min(rays_by_brick.size(), entries_.size());
  for (std::size_t b = 0; b < bricks; ++b) entries_[b].rays_served += rays_by_brick[b];
}

bool BrickCache::is_resident(uint32_t brick_id) const {
  std::lock_guard lock(mutex_);
  return brick_id < entries_.size() && entries_[brick_id].state == State::kReady;
}

CacheCounters BrickCache::counters() const {
  CacheCounters counters;
  {
    std::lock_guard lock(mutex_);
    counters = counters_;
  }
  if (tier_) counters.subtree = tier_->counters();
  return counters;
}

}  // namespace outcore
