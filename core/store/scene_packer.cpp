#include "core/store/scene_packer.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <optional>
#include <vector>

#include "core/store/brick_writer.h"
#include "core/store/generated_chunks.h"
#include "core/store/generated_partition.h"
#include "core/store/pack_context.h"
#include "core/store/pack_inputs.h"
#include "core/store/pack_output.h"
#include "core/store/spill_partition.h"
#include "core/store/store_commit.h"
#include "core/store/store_format.h"
#include "core/util/atomic_file.h"
#include "core/util/process_stats.h"

namespace outcore {

namespace {

namespace fs = std::filesystem;
using namespace packing;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// One pack, in order: check the options and the output, plan memory, open
// and scan the inputs, derive the brick target, partition into bricks (the
// generated fast path or the general spill path), commit the store.
class ScenePacker {
 public:
  explicit ScenePacker(const PackOptions& options) : context_(options), inputs_(context_) {}

  Expected<PackSummary> run();

 private:
  Status prepare_output();
  Status scan();
  Status plan_bricks();
  Status partition();
  PackSummary summarize(const Manifest& manifest) const;

  PackContext context_;
  PackInputs inputs_;
  fs::path output_;
  AtomicDirectory store_;
  ScanResult scan_;
  std::optional<GeneratedChunks> chunks_;  // generated inputs only
  BrickWriter bricks_;
};

Expected<PackSummary> ScenePacker::run() {
  const auto start = Clock::now();
  const PackOptions& options = context_.options;
  OUTCORE_RETURN_IF_ERROR(validate_pack_options(options));
  context_.memory = MemoryPlan::for_budget(options.memory_mb * kMiB);
  if (options.vertex_memory_mb > 0) context_.memory.source_vertices = options.vertex_memory_mb * kMiB;
  // The temporary directory comes first: file readers that resolve faces out
  // of core keep their spill files in it (each in a directory of its own,
  // removed with its source before the store is renamed into place).
  OUTCORE_RETURN_IF_ERROR(prepare_output());
  OUTCORE_RETURN_IF_ERROR(inputs_.open({context_.memory.source_vertices, store_.path()}));
  OUTCORE_RETURN_IF_ERROR(scan());
  OUTCORE_RETURN_IF_ERROR(plan_bricks());
  OUTCORE_RETURN_IF_ERROR(bricks_.create(store_.path() + "/" + kBrickDataFileName,
                                         context_.memory.brick_buffer, context_.memory.staging,
                                         scan_.triangles, options.show_progress));
  OUTCORE_RETURN_IF_ERROR(partition());
  // Readers' spill files go now, so that they never end up in the store.
  inputs_.close();
  chunks_.reset();
  const auto finish_start = Clock::now();
  OUTCORE_RETURN_IF_ERROR(bricks_.close(options.sync));
  OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
  OUTCORE_ASSIGN_OR_RETURN(const Manifest manifest,
                           commit_store(context_, scan_, bricks_.take_bricks(), store_, output_));
  PackSummary summary = summarize(manifest);
  summary.seconds = seconds_since(start);
  summary.phases.finish += seconds_since(finish_start);
  return summary;
}

Status ScenePacker::prepare_output() {
  std::error_code ec;
  output_ = normalized_output(context_.options.output);
  fs::create_directories(output_.parent_path(), ec);
  remove_stale_partials(output_);
  OUTCORE_RETURN_IF_ERROR(store_.create(output_.string()));
  context_.temp_dir = store_.path();
  return Status::Ok();
}

Status ScenePacker::scan() {
  std::vector<const RangeEmitter*> emitters = inputs_.range_emitters();
  if (emitters.empty()) return inputs_.scan(scan_);
  chunks_.emplace(context_, std::move(emitters), inputs_.descriptions());
  chunks_->make();
  // Groups are filtered from regenerated chunks, never spilled; no file inputs.
  context_.memory.spill_buffers = 0;
  context_.memory.read_chunk = 0;
  context_.memory.source_vertices = 0;
  return chunks_->scan(scan_);
}

Status ScenePacker::plan_bricks() {
  const PackOptions& options = context_.options;
  const uint64_t budget = options.memory_mb * kMiB;
  const uint64_t reserved = context_.memory.reserved();
  uint64_t capacity = budget > reserved ? (budget - reserved) / sizeof(PackedTriangle) : 0;
  if (options.max_group_triangles > 0) capacity = std::min(capacity, options.max_group_triangles);
  const auto brick_fits = [&](uint64_t triangles) {
    return triangles * sizeof(PackedTriangle) + reserved <= budget;
  };
  uint32_t target = kDefaultBrickTriangles;
  if (options.brick_triangles.has_value()) {
    target = *options.brick_triangles;
  } else if (scan_.triangles <= kSmallSceneTriangles && brick_fits(scan_.triangles)) {
    // The default: one brick for a small scene (when memory allows it).
    target = static_cast<uint32_t>(std::max<uint64_t>(scan_.triangles, 1));
  }
  context_.brick_triangles = target;
  context_.group_capacity = std::max<uint64_t>(capacity, target);
  if (context_.group_capacity < target || !brick_fits(target)) {
    return invalid_argument("--mem-mb " + std::to_string(options.memory_mb) + " is too small for bricks of " +
                            std::to_string(target) + " triangles");
  }
  return Status::Ok();
}

Status ScenePacker::partition() {
  SpillPartition general(context_, bricks_);
  if (!chunks_.has_value()) {
    return general.pack({inputs_.stream(scan_), inputs_.all_cheap_to_restream()}, scan_.triangles,
                        scan_.centroid_bounds, 0);
  }
  // A scope of its own: its group buffer goes before the commit.
  GeneratedPartition generated(context_, *chunks_, bricks_, general, inputs_.stream(scan_));
  return generated.pack(scan_);
}

PackSummary ScenePacker::summarize(const Manifest& manifest) const {
  PackSummary summary;
  summary.triangles = manifest.triangle_count;
  summary.degenerate_triangles = manifest.degenerate_count;
  summary.bricks = static_cast<uint32_t>(manifest.bricks.size());
  std::vector<uint32_t> sizes;
  for (const BrickRecord& b : manifest.bricks) sizes.push_back(b.triangle_count);
  std::sort(sizes.begin(), sizes.end());
  summary.brick_triangles_target = context_.brick_triangles;
  summary.min_brick_triangles = sizes.front();
  summary.median_brick_triangles = sizes[sizes.size() / 2];
  summary.max_brick_triangles = sizes.back();
  summary.upper_depth = manifest.upper.depth();
  std::error_code ec;
  summary.bytes_on_disk =
      fs::file_size(output_ / kBrickDataFileName, ec) + fs::file_size(output_ / kManifestFileName, ec);
  summary.spill_bytes_written = context_.spill_bytes;
  summary.out_of_core_levels = context_.levels;
  summary.peak_rss_bytes = peak_rss_bytes();
  summary.phases = context_.phases;
  return summary;
}

}  // namespace

Expected<PackSummary> pack_scene(const PackOptions& options) {
  return ScenePacker(options).run();
}

}  // namespace outcore
