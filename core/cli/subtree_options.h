// The subtree tier's command-line options (--subtree-dir, --subtree-dir-mb,
// --subtree-release-batch-mb),
// shared by `outcore trace` and `outcore serve`: checked and put into
// EngineOptions in one place so both commands give the same errors.
//
// Thread-safety: a function of its arguments.
#pragma once

#include <cstdint>
#include <string>

#include "core/cache/subtree_tier.h"
#include "core/query/query_engine.h"
#include "core/util/status.h"

namespace CLI {
class App;
}

namespace outcore {

struct SubtreeCliOptions {
  std::string dir;
  uint64_t dir_mb = 0;  // 0: unbounded
  uint64_t release_batch_mb = kDefaultReleaseBatchBytes >> 20;
};

// Adds the options to `command`, storing into `options`.
void add_subtree_options(CLI::App& command, SubtreeCliOptions& options);

// Sets options.subtree_dir / subtree_max_bytes / subtree_release_batch_bytes.
// INVALID_ARGUMENT naming the option when --subtree-dir is given for a brick
// structure other than bvh (options.brick_accel must already be set), or
// --subtree-dir-mb without --subtree-dir, or a size that does not fit in
// bytes.
Status apply_subtree_options(const SubtreeCliOptions& cli, EngineOptions& options);

}  // namespace outcore
