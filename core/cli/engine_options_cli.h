// The engine's command-line options shared by `outcore trace` and `outcore
// serve`: the brick cache (--cache-mb, --policy), the brick structure
// (--brick-accel and, for trace, --accel-opt, --triangle-test, --reference),
// the subtree tier (subtree_options.h) and the proxies (--no-proxies,
// --proxy-res). They are checked and put into EngineOptions in one place, so
// both commands accept the same values and give the same errors.
//
// Thread-safety: functions of their arguments.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/cli/subtree_options.h"
#include "core/query/query_engine.h"
#include "core/util/status.h"

namespace CLI {
class App;
}

namespace outcore {

struct EngineCliOptions {
  uint64_t cache_mb = 1024;
  std::string policy = "lru";
  std::string brick_accel = kDefaultBrickAccel;
  std::string brick_bounds = kDefaultBrickBounds;
  std::string dynamic_top_level = "bvh";
  std::string profile;  // --profile: the cost profile of --brick-accel auto
  SubtreeCliOptions subtree;
  bool no_proxies = false;
  std::optional<int64_t> proxy_res;  // unset: the default resolution
  // `trace` only (empty for `serve`, which has no such options).
  std::vector<std::string> accel_options;  // key=value
  std::string triangle_test;               // shorthand for --accel-opt triangle_test=NAME (bvh only)
  bool reference = false;                  // float64 ground truth: brick structure "reference"
};

// Adds --cache-mb, --policy, --brick-accel and the subtree options to
// `command`, storing into `options` (the proxies' options and trace's brick
// structure options are added by each command: their help differs).
void add_cache_options(CLI::App& command, EngineCliOptions& options);

// Checks `cli` and sets the cache, brick structure, subtree and proxy fields
// of `options`. INVALID_ARGUMENT naming the option (and the value) when one
// is out of range, malformed, or given with another it contradicts.
Status apply_engine_options(const EngineCliOptions& cli, EngineOptions& options);

}  // namespace outcore
