// CacheSimulator: replays a brick access trace (access_trace.h) against an
// eviction policy and a byte budget, offline and single-threaded, with the
// same policy classes and the same accounting as BrickCache:
// - a request for a resident brick is a hit (policy.on_access);
// - otherwise the brick's reservation (the trace's reserved_bytes, or its
//   bytes when that is 0) is made room for by evicting policy victims until
//   resident + reservation <= budget; the build then accounts its true bytes
//   (evicting more if they exceed the reservation, as BrickCache does for a
//   builder's overrun) and policy.on_insert gets the bytes and the cost;
// - a brick whose reservation exceeds the budget is RESOURCE_EXHAUSTED naming
//   it (BrickCache refuses it the same way).
// - a record's schedule hint (if any) goes to policy.on_schedule_hint first.
// Bytes come from the record being replayed. The cost of a simulated miss is
// the record's own build_seconds when the live cache missed there too (built,
// or loaded from the subtree tier: its load seconds), else the mean of that
// brick's measured misses in the trace (0 if it has none). So replaying a
// trace with the policy and budget it was recorded with gives exactly the live
// cache's misses (builds + subtree loads) and bytes (tested), as long as the
// live run acquired one brick at a time (the engine's reordered batches do;
// concurrent batches add pins and waits the replay does not model: a "wait"
// record is replayed as an ordinary request).
//
// Thread-safety: functions of their arguments only; run several in parallel
// on one trace freely.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/cache/access_trace.h"
#include "core/cache/eviction_policy.h"

namespace outcore {

struct SimulationResult {
  std::string policy;  // a policy name, or "opt"
  std::string detail;  // for opt: the rule that gave the result
  uint64_t budget_bytes = 0;
  uint64_t requests = 0;
  uint64_t hits = 0;
  uint64_t misses = 0;  // = builds (live: builds + subtree tier loads)
  uint64_t evictions = 0;
  uint64_t bytes_built = 0;
  double build_seconds = 0;
  uint64_t peak_resident_bytes = 0;  // reservations included

  double miss_ratio() const {
    return requests ? static_cast<double>(misses) / static_cast<double>(requests) : 0.0;
  }
};

// What a replay needs per brick, computed once per trace.
struct TraceProfile {
  std::vector<double> mean_build_seconds;  // per brick id, over its miss and load records
  uint64_t working_set_bytes = 0;          // sum over distinct bricks of their largest bytes
  uint64_t largest_reservation = 0;        // the smallest budget every request fits in
  uint32_t largest_brick_id = 0;           // whose reservation that is
  uint32_t distinct_bricks = 0;

  static TraceProfile of(const AccessTrace& trace);
  // The reservation of record r (reserved_bytes, or bytes when 0).
  static uint64_t reservation(const AccessRecord& r) { return r.reserved_bytes ? r.reserved_bytes : r.bytes; }
  // Whether the live cache made the brick resident at record r (a build or a
  // subtree tier load), so its build_seconds were measured there.
  static bool is_measured_miss(const AccessRecord& r) {
    return r.outcome == AccessOutcome::kMiss || r.outcome == AccessOutcome::kLoad;
  }
  // The cost a simulated build of record r is charged (see above).
  double cost(const AccessRecord& r) const {
    return is_measured_miss(r) ? r.build_seconds : mean_build_seconds[r.brick];
  }
};

// RESOURCE_EXHAUSTED naming the brick (and its record) when a reservation
// exceeds budget_bytes; INVALID_ARGUMENT for a zero budget.
Status check_budget(const AccessTrace& trace, const TraceProfile& profile, uint64_t budget_bytes);

// Replays `trace` through `policy` (fresh: set_budget is called here).
Expected<SimulationResult> simulate_policy(const AccessTrace& trace, const TraceProfile& profile,
                                           EvictionPolicy& policy, uint64_t budget_bytes);
// The same, creating the policy by name (NOT_FOUND for an unknown one).
Expected<SimulationResult> simulate_policy(const AccessTrace& trace, const TraceProfile& profile,
                                           const std::string& policy_name, uint64_t budget_bytes);

}  // namespace outcore
