#include "core/cli/subtree_options.h"

#include <CLI/CLI.hpp>

#include <limits>
#include <string>
#include <utility>

#include "core/accel/brick_accel_factory.h"

namespace outcore {

namespace {
bool saves_bricks(const std::string& brick_accel) {
  auto builder = make_brick_builder(brick_accel, {});
  return builder.ok() && (*builder)->serializer() != nullptr;
}
}  // namespace

void add_subtree_options(CLI::App& command, SubtreeCliOptions& options) {
  command.add_option("--subtree-dir", options.dir,
                     "Save built bricks to this directory and load them from it on later misses instead of "
                     "building (--brick-accel bvh, kdtree, bsp, grid, hgrid, octree, quadtree or auto; "
                     "docs/CACHE_TUNING.md)");
  command
      .add_option("--subtree-dir-mb", options.dir_mb,
                  "Most MiB of brick files kept in --subtree-dir, least recently used deleted first (0: "
                  "unbounded)")
      ->check(CLI::Range(uint64_t{0}, std::numeric_limits<uint64_t>::max() >> 20))
      ->capture_default_str();
  command
      .add_option("--subtree-release-batch-mb", options.release_batch_mb,
                  "Release the pages of evicted bricks loaded from --subtree-dir in batches of this many MiB "
                  "of mappings (held in RSS until released; 0: each brick at once; docs/CACHE_TUNING.md)")
      ->check(CLI::Range(uint64_t{0}, std::numeric_limits<uint64_t>::max() >> 20))
      ->capture_default_str();
}

Status apply_subtree_options(const SubtreeCliOptions& cli, EngineOptions& options) {
  constexpr uint64_t kMaxMiB = std::numeric_limits<uint64_t>::max() >> 20;
  if (cli.dir.empty()) {
    if (cli.dir_mb != 0) return invalid_argument("--subtree-dir-mb needs --subtree-dir");
    if (cli.release_batch_mb != (kDefaultReleaseBatchBytes >> 20)) {
      return invalid_argument("--subtree-release-batch-mb needs --subtree-dir");
    }
    return Status::Ok();
  }
  // Only structures whose builder offers a BrickSerializer can be saved.
  if (!saves_bricks(options.brick_accel)) {
    std::string savable;
    for (const std::string& name : brick_accel_names()) {
      if (saves_bricks(name)) savable += (savable.empty() ? "" : "|") + name;
    }
    return invalid_argument("--subtree-dir needs --brick-accel " + savable + " (got '" + options.brick_accel +
                            "', whose bricks cannot be saved)");
  }
  for (const auto& [name, mib] : {std::pair{"--subtree-dir-mb", cli.dir_mb},
                                  std::pair{"--subtree-release-batch-mb", cli.release_batch_mb}}) {
    if (mib > kMaxMiB) {
      return invalid_argument(std::string(name) + " must be at most " + std::to_string(kMaxMiB) + ", got " +
                              std::to_string(mib));
    }
  }
  options.subtree_dir = cli.dir;
  options.subtree_max_bytes = cli.dir_mb << 20;
  options.subtree_release_batch_bytes = cli.release_batch_mb << 20;
  return Status::Ok();
}

}  // namespace outcore
