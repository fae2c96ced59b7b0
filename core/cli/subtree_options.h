// The subtree tier's command-line options (--subtree-dir, --subtree-dir-mb),
// shared by `outcore trace` and `outcore serve`: checked and put into
// EngineOptions in one place so both commands give the same errors.
//
// Thread-safety: a function of its arguments.
#pragma once

#include <cstdint>
#include <string>

#include "core/query/query_engine.h"
#include "core/util/status.h"

namespace CLI {
class App;
}

namespace outcore {

// Adds --subtree-dir and --subtree-dir-mb to `command`, storing into the two.
void add_subtree_options(CLI::App& command, std::string& subtree_dir, uint64_t& subtree_dir_mb);

// Sets options.subtree_dir / subtree_max_bytes. INVALID_ARGUMENT naming the
// option when --subtree-dir is given for a brick structure other than bvh
// (options.brick_accel must already be set), or --subtree-dir-mb without
// --subtree-dir, or a size that does not fit in bytes.
Status apply_subtree_options(const std::string& subtree_dir, uint64_t subtree_dir_mb, EngineOptions& options);

}  // namespace outcore
