// Belady's offline optimum (OPT / MIN; Belady 1966) for a brick access trace:
// knowing the whole future, evict the resident brick whose next request is
// furthest away (never-again first). Replayed with the same accounting as
// CacheSimulator (reservation before a build, true bytes after).
//
// With equal brick sizes this furthest-next-use rule is exact: no policy can
// build fewer bricks on the trace. With variable sizes exact OPT is NP-hard
// (it contains knapsack); there the rule is a strong heuristic, and
// simulate_opt also runs a size-aware rule — evict the brick with the largest
// (distance to next use) × bytes, i.e. the one that frees the most
// byte-requests of room — and reports whichever builds fewer bricks (then
// fewer bytes). On variable-size traces "OPT" is therefore an upper bound of
// the true optimum, checked empirically (core/cache/belady_test.cpp) never to
// be beaten by the online policies on random traces.
//
// Cost: O(n log n) for furthest-next-use; the size-aware rule scans the
// resident bricks at each eviction, O(misses × resident).
//
// Thread-safety: functions of their arguments only.
#pragma once

#include <cstdint>

#include "core/cache/access_trace.h"
#include "core/cache/cache_simulator.h"

namespace outcore {

enum class BeladyRule {
  kFurthestNextUse,  // "furthest-next-use"
  kSizeWeighted,     // "size-weighted": largest distance × bytes
};
const char* belady_rule_name(BeladyRule rule);

// One rule; the result's policy is "opt", its detail the rule's name.
Expected<SimulationResult> simulate_belady(const AccessTrace& trace, const TraceProfile& profile,
                                           uint64_t budget_bytes, BeladyRule rule);
// The better of the rules (furthest-next-use alone when all sizes are equal).
Expected<SimulationResult> simulate_opt(const AccessTrace& trace, const TraceProfile& profile,
                                        uint64_t budget_bytes);

}  // namespace outcore
