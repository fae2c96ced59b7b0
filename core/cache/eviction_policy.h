// EvictionPolicy: decides which resident, unpinned brick the cache evicts next.
// The cache tells the policy its budget once, then about every insert, access
// and erase; the policy only ranks. Policies are created by name
// (make_eviction_policy: lru, clock, lfu, arc, s3fifo, gdsf, schedule) so `trace`,
// `serve` and `cache-sim` can select them; the simulator drives the very same
// classes, so a replay ranks exactly as the live cache did.
//
// Contract of the calls (BrickCache and CacheSimulator both follow it):
// - set_budget once, before anything else;
// - on_insert when a brick becomes resident (after its build), with its
//   accounted bytes and the measured load+build seconds (its miss cost);
// - on_access on every later acquisition of a resident brick (a hit);
// - choose_victim when room is needed; it may reorganise internal state (a
//   CLOCK hand, S3-FIFO promotions) but only on_erase forgets a brick, and the
//   caller erases the brick it was given before asking again;
// - on_erase when a brick leaves the cache (policies with ghost lists remember
//   it there);
// - on_schedule_hint (optional) with the bricks the caller knows it will
//   request next, soonest first; the default ignores it. This is where a
//   schedule-aware policy (Belady on the known part of the schedule) learns
//   the queue order of the engine's reordered batches.
//
// Thread-safety: none of its own; the cache calls it under the cache's lock.
// Called once per brick acquisition, never per ray.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

class EvictionPolicy {
 public:
  virtual ~EvictionPolicy() = default;
  // The cache's byte budget. Policies that size queues or ghost lists in bytes
  // (arc, s3fifo) need it; without a call they behave as if it were unlimited.
  virtual void set_budget(uint64_t budget_bytes) { (void)budget_bytes; }
  virtual void on_insert(uint32_t brick, uint64_t bytes, double build_seconds) = 0;
  virtual void on_access(uint32_t brick) = 0;
  virtual void on_erase(uint32_t brick) = 0;
  // The brick to evict among those for which evictable(brick) is true, or
  // nothing if none is.
  virtual std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) = 0;
  // The bricks about to be requested, soonest first; replaces the last hint.
  virtual void on_schedule_hint(std::span<const uint32_t> upcoming) { (void)upcoming; }
  // True when on_schedule_hint is used: callers skip the work of hinting otherwise.
  virtual bool wants_schedule_hint() const { return false; }
  virtual const std::string& name() const = 0;
};

// NOT_FOUND naming the unknown name and listing the known ones.
Expected<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name);
std::vector<std::string> eviction_policy_names();

}  // namespace outcore
