#include "core/cli/subtree_options.h"

#include <CLI/CLI.hpp>

#include <limits>

namespace outcore {

void add_subtree_options(CLI::App& command, std::string& subtree_dir, uint64_t& subtree_dir_mb) {
  command.add_option("--subtree-dir", subtree_dir,
                     "Save built bricks to this directory and load them from it on later misses instead of "
                     "building (--brick-accel bvh only; docs/CACHE_TUNING.md)");
  command
      .add_option("--subtree-dir-mb", subtree_dir_mb,
                  "Most MiB of brick files kept in --subtree-dir, least recently used deleted first (0: "
                  "unbounded)")
      ->capture_default_str();
}

Status apply_subtree_options(const std::string& subtree_dir, uint64_t subtree_dir_mb,
                             EngineOptions& options) {
  if (subtree_dir.empty()) {
    if (subtree_dir_mb != 0) return invalid_argument("--subtree-dir-mb needs --subtree-dir");
    return Status::Ok();
  }
  // Only bvh bricks can be serialised (BrickBuilder::serializer()).
  if (options.brick_accel != "bvh") {
    return invalid_argument("--subtree-dir needs --brick-accel bvh (got '" + options.brick_accel +
                            "', whose bricks cannot be saved)");
  }
  if (subtree_dir_mb > (std::numeric_limits<uint64_t>::max() >> 20)) {
    return invalid_argument("--subtree-dir-mb must be at most " +
                            std::to_string(std::numeric_limits<uint64_t>::max() >> 20) + ", got " +
                            std::to_string(subtree_dir_mb));
  }
  options.subtree_dir = subtree_dir;
  options.subtree_max_bytes = subtree_dir_mb << 20;
  return Status::Ok();
}

}  // namespace outcore
