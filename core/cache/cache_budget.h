// The smallest brick-cache budget a scene can be traced under: the largest
// reservation the brick builder makes for any of the scene's bricks (the
// cache reserves BrickBuilder::reserve_bytes before each build and refuses a
// brick whose reservation exceeds the whole budget). Checked when a scene is
// opened (QueryEngine::create), so that a budget too small is an error at
// start, naming the smallest workable budget, instead of a server that starts
// and then fails every query that reaches the large brick; `outcore info`
// prints it.
//
// Thread-safety: pure functions of their arguments.
#pragma once

#include <cstdint>
#include <string>

#include "core/accel/brick_accel_factory.h"
#include "core/store/manifest.h"
#include "core/util/status.h"

namespace outcore {

struct MinimumCacheBudget {
  uint64_t bytes = 0;           // the largest reservation; 0 for a scene without bricks
  uint32_t brick_id = 0;        // the brick that needs it
  uint32_t triangle_count = 0;  // that brick's triangles
  // `bytes` in whole MiB, rounded up (what to give --cache-mb).
  uint64_t mib() const { return (bytes + (uint64_t{1} << 20) - 1) >> 20; }
};

MinimumCacheBudget minimum_cache_budget(const Manifest& manifest, const BrickBuilder& builder);

// OK when `budget_bytes` holds the largest reservation, else INVALID_ARGUMENT
// naming the brick, the builder, both sizes and the smallest workable budget
// in MiB.
Status check_cache_budget(const Manifest& manifest, const BrickBuilder& builder, uint64_t budget_bytes);

// "1.25 MiB (1310720 bytes)": MiB for people, bytes for small test budgets.
std::string describe_bytes(uint64_t bytes);

}  // namespace outcore
