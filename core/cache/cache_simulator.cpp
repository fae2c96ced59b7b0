#include "core/cache/cache_simulator.h"

#include <algorithm>
#include <cstdio>

namespace outcore {
namespace {

std::string mib(uint64_t bytes) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.2f MiB (%llu bytes)", static_cast<double>(bytes) / 1048576.0,
                static_cast<unsigned long long>(bytes));
  return text;
}

}  // namespace

TraceProfile TraceProfile::of(const AccessTrace& trace) {
  TraceProfile profile;
  uint32_t bricks = trace.info.bricks;
  for (const AccessRecord& r : trace.records) bricks = std::max(bricks, r.brick + 1);
  std::vector<double> seconds(bricks, 0.0);
  std::vector<uint32_t> builds(bricks, 0);
  std::vector<uint64_t> largest(bricks, 0);
  std::vector<uint8_t> seen(bricks, 0);
  for (const AccessRecord& r : trace.records) {
    if (is_measured_miss(r)) {
      seconds[r.brick] += r.build_seconds;
      ++builds[r.brick];
    }
    largest[r.brick] = std::max(largest[r.brick], r.bytes);
    profile.distinct_bricks += seen[r.brick] == 0;
    seen[r.brick] = 1;
    const uint64_t reserve = reservation(r);
    if (reserve > profile.largest_reservation) {
      profile.largest_reservation = reserve;
      profile.largest_brick_id = r.brick;
    }
  }
  profile.mean_build_seconds.resize(bricks, 0.0);
  for (uint32_t b = 0; b < bricks; ++b) {
    if (builds[b]) profile.mean_build_seconds[b] = seconds[b] / builds[b];
    profile.working_set_bytes += largest[b];
  }
  return profile;
}

Status check_budget(const AccessTrace& trace, const TraceProfile& profile, uint64_t budget_bytes) {
  if (budget_bytes == 0) return invalid_argument("the cache budget must be positive");
  if (profile.largest_reservation <= budget_bytes) return Status::Ok();
  for (const AccessRecord& r : trace.records) {
    if (TraceProfile::reservation(r) > budget_bytes) {
      return resource_exhausted(
          "brick " + std::to_string(r.brick) + " (trace record " + std::to_string(r.seq) + ") needs up to " +
          mib(TraceProfile::reservation(r)) + ", more than the cache budget of " + mib(budget_bytes) +
          "; the smallest budget this trace can be replayed with is " + mib(profile.largest_reservation));
    }
  }
  return Status::Ok();
}

Expected<SimulationResult> simulate_policy(const AccessTrace& trace, const TraceProfile& profile,
                                           EvictionPolicy& policy, uint64_t budget_bytes) {
  OUTCORE_RETURN_IF_ERROR(check_budget(trace, profile, budget_bytes));
  SimulationResult result;
  result.policy = policy.name();
  result.budget_bytes = budget_bytes;
  policy.set_budget(budget_bytes);

  const std::size_t bricks = profile.mean_build_seconds.size();
  std::vector<uint8_t> resident(bricks, 0);
  std::vector<uint64_t> bytes_of(bricks, 0);
  uint64_t resident_bytes = 0;
  const std::function<bool(uint32_t)> evictable = [&](uint32_t b) { return b < bricks && resident[b] != 0; };
  // Evicts until `extra` more bytes fit; false if the policy runs out.
  const auto make_room = [&](uint64_t extra) {
    while (resident_bytes + extra > budget_bytes) {
      const std::optional<uint32_t> victim = policy.choose_victim(evictable);
      if (!victim || !evictable(*victim)) return false;
      policy.on_erase(*victim);
      resident[*victim] = 0;
      resident_bytes -= bytes_of[*victim];
      bytes_of[*victim] = 0;
      ++result.evictions;
    }
    return true;
  };

  for (const AccessRecord& r : trace.records) {
    if (r.has_hint) policy.on_schedule_hint(r.hint);
    ++result.requests;
    if (resident[r.brick]) {
      ++result.hits;
      policy.on_access(r.brick);
      continue;
    }
    const uint64_t reserve = TraceProfile::reservation(r);
    if (!make_room(reserve)) {
      return internal_error("policy '" + policy.name() + "' found no victim while " +
                            std::to_string(resident_bytes) + " bytes were resident (record " +
                            std::to_string(r.seq) + ")");
    }
    result.peak_resident_bytes = std::max(result.peak_resident_bytes, resident_bytes + reserve);
    // A build larger than its reservation makes room for the excess, as
    // BrickCache does for a builder's overrun (best effort, no error).
    if (r.bytes > reserve) (void)make_room(r.bytes);
    resident[r.brick] = 1;
    bytes_of[r.brick] = r.bytes;
    resident_bytes += r.bytes;
    result.peak_resident_bytes = std::max(result.peak_resident_bytes, resident_bytes);
    const double cost = profile.cost(r);
    policy.on_insert(r.brick, r.bytes, cost);
    ++result.misses;
    result.bytes_built += r.bytes;
    result.build_seconds += cost;
  }
  return result;
}

Expected<SimulationResult> simulate_policy(const AccessTrace& trace, const TraceProfile& profile,
                                           const std::string& policy_name, uint64_t budget_bytes) {
  OUTCORE_ASSIGN_OR_RETURN(auto policy, make_eviction_policy(policy_name));
  return simulate_policy(trace, profile, *policy, budget_bytes);
}

}  // namespace outcore
