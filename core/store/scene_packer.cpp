#include "core/store/scene_packer.h"

#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>

#include "core/gen/generator.h"
#include "core/gen/generator_factory.h"
#include "core/geometry/coordinate_limits.h"
#include "core/io/source_factory.h"
#include "core/proxy/proxy_file.h"
#include "core/store/brick_partitioner.h"
#include "core/store/centroid_grid.h"
#include "core/store/manifest.h"
#include "core/store/store_format.h"
#include "core/upper/upper_hierarchy_builder.h"
#include "core/util/buffered_file.h"
#include "core/util/cancellation.h"
#include "core/util/checksum.h"
#include "core/util/process_stats.h"
#include "core/util/progress.h"
#include "core/util/temporary_directory.h"

namespace outcore {

namespace {

namespace fs = std::filesystem;

constexpr uint64_t kMiB = 1024 * 1024;
// How the memory bound is shared: fixed-size helpers scale with the budget so
// that small budgets still leave most of it for the in-memory triangle group.
struct MemoryPlan {
  uint32_t grid_cells;          // centroid grid: 1/16 of the budget, 4 K .. 256 K cells
  uint64_t brick_buffer;        // two of them: the brick file writes asynchronously
  uint64_t staging;             // brick payload staging
  uint64_t read_chunk;          // spill reads
  uint64_t spill_buffers;       // shared by all spill writers of one level
  uint64_t batches = 4 * kMiB;  // source and packed batches, filters
  // OBJ/PLY readers: vertex positions, or the buffers that resolve faces out
  // of core when a file's vertices exceed this (SourceOptions). Held whenever a
  // file input streams, so also while a group is in memory.
  uint64_t source_vertices;
  // Generated inputs only (pack_generated): the chunk table, the filter
  // pipeline's per-token chunk buffers, and each cell's subgroup.
  uint64_t chunk_table = 0;
  uint64_t filter_buffers = 0;
  // Meshes generators hold for their lifetime (gen:city's base), at most
  // half of the budget (open_sources).
  uint64_t generator_meshes = 0;
  uint64_t reserved() const {
    return uint64_t{grid_cells} * (sizeof(CellStats) + 2 * sizeof(uint32_t)) + 2 * brick_buffer + staging +
           2 * read_chunk + spill_buffers + batches + source_vertices + chunk_table + filter_buffers +
           generator_meshes;
  }
  static MemoryPlan for_budget(uint64_t budget) {
    MemoryPlan plan{};
    plan.grid_cells = static_cast<uint32_t>(
        std::clamp<uint64_t>(budget / 16 / (sizeof(CellStats) + sizeof(uint32_t)), 1u << 12, 1u << 18));
    plan.brick_buffer = std::clamp<uint64_t>(budget / 64, 256 * 1024, 4 * kMiB);
    plan.staging = std::clamp<uint64_t>(budget / 128, 64 * 1024, kMiB);
    plan.read_chunk = std::clamp<uint64_t>(budget / 64, 256 * 1024, 4 * kMiB);
    plan.spill_buffers = budget / 16;
    plan.source_vertices = budget / 8;
    return plan;
  }
};
constexpr uint32_t kMaxGroupsPerLevel = 256;
constexpr uint32_t kMaxRecursionDepth = 16;

// Generated inputs are cut into chunks of primitive ids that are generated on
// all cores (Generator::emit_range) and merged in chunk order, so the result
// does not depend on the thread count. These constants feed the MemoryPlan, so
// they must not depend on the machine either.
constexpr uint32_t kFilterTokens = 8;     // chunks in flight in the filter pipeline
constexpr uint32_t kBrickTokens = 4;      // subgroups in flight in the brick pipeline
constexpr int kHistogramCopies = 4;       // per-thread centroid histograms, merged exactly
constexpr uint64_t kMaxChunks = 1 << 16;  // chunks grow with the scene beyond this
// A group in memory is cut along grid planes into subgroups of about this many
// bricks, each partitioned on its own: one scatter pass replaces the top
// levels of binary partitioning, and subgroups fit in cache and run in parallel.
constexpr uint64_t kSubgroupBricks = 16;
constexpr uint64_t kMinSubgroupTriangles = 1 << 16;
// A chunk whose centroid box covers more cells than this is assumed to touch
// every group (its cells are not enumerated).
constexpr uint64_t kMaxChunkCellsScanned = 1 << 16;

// Primitive ids [first, last) of one generated input.
struct InputChunk {
  uint32_t input = 0;
  uint64_t first = 0, last = 0;
  Aabb centroid_bounds;  // from the scan; tells which groups the chunk can touch
};

// Per-chunk results of the scan, merged in chunk order.
struct ChunkScan {
  uint64_t degenerate = 0;
  uint64_t first_bad = ~uint64_t{0};  // primitive id of the first triangle vertex_problem() refuses, or none
  const char* problem = nullptr;      // and why
  Aabb bounds, centroid_bounds;
};

// Absolute, and "scene/" names the directory scene, not an entry inside it.
fs::path normalized_output(const std::string& output) {
  std::error_code ec;
  fs::path path = fs::absolute(output, ec).lexically_normal();
  if (!path.has_filename()) path = path.parent_path();
  return path;
}

// Wall time per packer phase, reported in the summary.
class PhaseTimer {
 public:
  explicit PhaseTimer(double& sink) : sink_(sink), start_(std::chrono::steady_clock::now()) {}
  ~PhaseTimer() { sink_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }

 private:
  double& sink_;
  std::chrono::steady_clock::time_point start_;
};

// Triangles of a group in memory, reused across groups (one allocation, pages
// faulted once); not value-initialised, every slot is written before it is read.
struct TriangleBuffer {
  struct Free {
    void operator()(PackedTriangle* p) const { std::free(p); }
  };
  std::unique_ptr<PackedTriangle, Free> data;
  uint64_t capacity = 0;
  Status reserve(uint64_t count) {
    if (count <= capacity) return Status::Ok();
    data.reset();
    data.reset(static_cast<PackedTriangle*>(std::malloc(count * sizeof(PackedTriangle))));
    if (!data) return resource_exhausted("cannot allocate " + std::to_string(count) + " triangles");
    capacity = count;
    return Status::Ok();
  }
};

using PackedBatchFn = std::function<Status(std::span<const PackedTriangle>)>;
// A re-streamable set of tagged triangles: the inputs themselves or a spill file.
using PackedStream = std::function<Status(const PackedBatchFn&)>;
struct SourceStream {
  PackedStream stream;
  bool cheap = false;  // re-streaming beats a spill round trip
};
// Which group a triangle (and its position in the stream) belongs to.
using GroupFn = std::function<uint32_t(const PackedTriangle&, uint64_t)>;

struct ScanResult {
  std::vector<InputRecord> inputs;
  uint64_t triangles = 0;
  uint64_t degenerate = 0;
  Aabb bounds;
  Aabb centroid_bounds;
};

class ScenePacker {
 public:
  explicit ScenePacker(const PackOptions& options) : options_(options) {}

  Expected<PackSummary> run();

 private:
  Status validate_options() const;
  // OK when nothing is at `output`, or --force is given and it may be replaced.
  Status check_output(const fs::path& output) const;
  // --force: whether the existing `output` may be replaced (an Outcore store
  // holding no input of this pack); an error naming what it is otherwise.
  Status check_replaceable(const fs::path& output) const;
  void remove_stale_partials(const fs::path& output) const;
  Status open_sources(const SourceOptions& source_options);
  Status scan();
  PackedStream input_stream();
  Status pack_stream(const SourceStream& source, uint64_t count, const Aabb& centroid_bounds, uint32_t depth);
  Status pack_sequential_chunks(const SourceStream& source, uint64_t count, uint32_t depth);
  Status distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                    const GroupFn& group_of, uint32_t depth);
  Status build_group_in_memory(const PackedStream& stream, uint64_t count);
  Status write_brick(std::span<const PackedTriangle> triangles, const Aabb& bounds);
  Status check_cancel() const { return cancel_requested() ? cancelled("pack interrupted") : Status::Ok(); }

  // Generated inputs with fast ranges: chunked, parallel, no spill files.
  bool collect_ranged_generators();
  void make_chunks();
  template <class Fn>
  Status generate_chunk(const InputChunk& chunk, Fn&& fn) const;
  Status scan_chunks();
  Status pack_generated();
  template <class Classify>
  Status fill_group(std::span<const uint32_t> chunk_ids, const Classify& classify,
                    std::span<const uint64_t> sub_counts, PackedTriangle* out);
  Status write_subgroups(PackedTriangle* data, std::span<const uint64_t> sub_counts);

  const PackOptions& options_;
  std::vector<std::unique_ptr<TriangleSource>> sources_;
  ScanResult scan_;
  MemoryPlan memory_{};
  uint64_t group_capacity_ = 0;   // triangles that fit in memory at once
  uint32_t brick_triangles_ = 0;  // the target in effect: the option's, or the default's (run())
  TemporaryDirectory temp_;
  BufferedFileWriter brick_file_;
  std::vector<char> staging_;
  std::vector<BrickRecord> bricks_;
  std::unique_ptr<ProgressBar> brick_progress_;
  uint64_t spill_bytes_ = 0;
  uint32_t levels_ = 0;
  uint32_t spill_serial_ = 0;
  std::vector<const Generator*> generators_;  // sources_ as generators (fast path only)
  std::vector<InputChunk> chunks_;
  uint64_t max_chunk_ = 0;  // triangles
  TriangleBuffer group_buffer_;
  PackPhaseSeconds phases_;
};

Status ScenePacker::validate_options() const {
  if (options_.inputs.empty()) return invalid_argument("no inputs given");
  if (options_.output.empty()) return invalid_argument("no output store given (-o)");
  if (options_.brick_triangles.has_value() &&
      (*options_.brick_triangles == 0 || *options_.brick_triangles > kMaxBrickTriangles)) {
    return invalid_argument("--brick-tris must be between 1 and " + std::to_string(kMaxBrickTriangles) +
                            ", got " + std::to_string(*options_.brick_triangles));
  }
  if (options_.memory_mb < kMinPackMemoryMb) {
    return invalid_argument("--mem-mb must be at least " + std::to_string(kMinPackMemoryMb) + ", got " +
                            std::to_string(options_.memory_mb));
  }
  if (options_.vertex_memory_mb > options_.memory_mb / 2) {
    return invalid_argument("--vertex-mem-mb must be at most half of --mem-mb (" +
                            std::to_string(options_.memory_mb / 2) + "), got " +
                            std::to_string(options_.vertex_memory_mb));
  }
  if (options_.inputs.size() >= 0xffffffffull) return invalid_argument("too many inputs");
  return check_output(normalized_output(options_.output));
}

Status ScenePacker::check_output(const fs::path& output) const {
  std::error_code ec;
  // symlink_status: a dangling link at -o is something there too.
  if (!fs::exists(fs::symlink_status(output, ec))) return Status::Ok();
  if (!options_.overwrite) {
    return already_exists("output " + options_.output + " already exists (use --force to replace it)");
  }
  return check_replaceable(output);
}

Status ScenePacker::check_replaceable(const fs::path& output) const {
  std::error_code ec;
  // An input inside the target (or the target itself) would be deleted with it.
  for (const std::string& input : options_.inputs) {
    if (input.starts_with("gen:")) continue;
    const fs::path real = fs::canonical(input, ec);
    if (ec) continue;  // a missing input fails when it is opened
    for (fs::path p = real;; p = p.parent_path()) {
      if (fs::equivalent(p, output, ec)) {
        return invalid_argument("refusing to replace " + output.string() + " (--force): input '" + input +
                                "' of this pack " + (p == real ? "is that path" : "lies inside it"));
      }
      if (p == p.parent_path()) break;
    }
  }
  const std::string refusal = "refusing to replace " + output.string() + " (--force replaces only a store): ";
  const fs::file_status status = fs::symlink_status(output, ec);
  if (fs::is_symlink(status))
    return failed_precondition(refusal + "it is a symbolic link; give the store's own path");
  if (!fs::is_directory(status)) {
    return failed_precondition(
        refusal + (fs::is_regular_file(status) ? "it is a regular file" : "it is not a directory") +
        ", not an Outcore store");
  }
  // A store is what this packer writes: the manifest with the store's magic
  // (of any format version, or damaged: repacking is how such a store is
  // mended) and nothing but store files, so that nothing else can be lost.
  const std::string manifest = (output / kManifestFileName).string();
  char magic[sizeof kManifestMagic] = {};
  {
    std::ifstream in(manifest, std::ios::binary);
    in.read(magic, sizeof magic);
    if (!in || std::memcmp(magic, kManifestMagic, sizeof magic) != 0)
      return failed_precondition(refusal + "it is not an Outcore store (no " +
                                 std::string(kManifestFileName) + " with the store's magic)");
  }
  for (fs::directory_iterator it(output, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const bool store_file = name == kManifestFileName || name == kBrickDataFileName ||
                            name == kProxyFileName ||
                            name.starts_with("." + std::string(kProxyFileName) + ".tmp-") ||
                            name.starts_with(std::string(kProxyFileName) + ".partial-");
    if (!store_file)
      return failed_precondition(refusal + "it holds '" + name + "', which is not part of an Outcore store");
  }
  if (ec) return io_error("cannot list " + output.string() + ": " + ec.message());
  return Status::Ok();
}

void ScenePacker::remove_stale_partials(const fs::path& output) const {
  // A pack that died (SIGKILL, power loss) could not remove its temporary
  // directory; left alone, these pile up and fill the disk.
  for (const StalePartial& stale : find_stale_partials(output.string())) {
    std::error_code ec;
    fs::remove_all(stale.path, ec);
    if (ec) {
      spdlog::warn("cannot remove {}, left by pack process {} (no longer running): {}", stale.path, stale.pid,
                   ec.message());
    } else {
      spdlog::warn("removed {}, left by pack process {} (no longer running)", stale.path, stale.pid);
    }
  }
}

Status ScenePacker::open_sources(const SourceOptions& source_options) {
  // Half the budget, as for --vertex-mem-mb: the rest must still hold a brick.
  const uint64_t allowance = options_.memory_mb * kMiB / 2;
  const std::string origin = "half of --mem-mb " + std::to_string(options_.memory_mb);
  for (const std::string& spec : options_.inputs) {
    OUTCORE_RETURN_IF_ERROR(check_cancel());
    GeneratorOptions generator_options;
    // Bases of several cities are held at once, so each gets what is left (a
    // held base never exceeds the limit it was read under: at least 1 is left).
    generator_options.mesh_memory_bytes = std::max<uint64_t>(1, allowance - memory_.generator_meshes);
    generator_options.mesh_memory_origin =
        memory_.generator_meshes == 0 ? origin : "what the earlier gen:city bases left of " + origin;
    auto source = spec.starts_with("gen:") ? make_generator(spec, generator_options)
                                           : open_triangle_source(spec, source_options);
    if (!source.ok()) return source.status();
    memory_.generator_meshes += (*source)->held_memory_bytes();
    sources_.push_back(std::move(source).value());
  }
  return Status::Ok();
}

Status ScenePacker::scan() {
  PhaseTimer timer(phases_.scan);
  ProgressBar bar("scan", 0, "tris", options_.show_progress);
  for (size_t g = 0; g < sources_.size(); ++g) {
    InputRecord record;
    record.spec = sources_[g]->description();
    auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
      OUTCORE_RETURN_IF_ERROR(check_cancel());
      for (const Triangle& t : batch) {
        if (const char* problem = vertex_problem(t)) {
          return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "': triangle " +
                                  std::to_string(record.triangle_count) + " " + problem);
        }
        record.degenerate_count += t.is_degenerate();
        scan_.bounds.extend(t.bounds());
        scan_.centroid_bounds.extend(t.centroid());
        ++record.triangle_count;
      }
      bar.advance(batch.size());
      return Status::Ok();
    });
    OUTCORE_RETURN_IF_ERROR(sources_[g]->stream(sink));
    if (record.triangle_count >= 0xffffffffull) {
      return invalid_argument(
          "input " + std::to_string(g) + " '" + record.spec + "' has " +
          std::to_string(record.triangle_count) +
          " triangles; primitive ids are 32-bit, so an input may hold at most 4294967294");
    }
    scan_.triangles += record.triangle_count;
    scan_.degenerate += record.degenerate_count;
    scan_.inputs.push_back(std::move(record));
  }
  bar.finish();
  // A file that is not what it claims (an OBJ of unknown statements) parses
  // to nothing; silently packing the rest would hide the mistake.
  for (size_t g = 0; g < scan_.inputs.size(); ++g) {
    if (scan_.inputs[g].triangle_count != 0) continue;
    const std::string what =
        "input " + std::to_string(g) + " '" + scan_.inputs[g].spec + "' has no triangles";
    if (options_.strict) return invalid_argument(what + " (--strict)");
    if (scan_.triangles != 0) spdlog::warn("{}; it contributes nothing to the scene", what);
  }
  if (scan_.triangles == 0) return invalid_argument("the scene is empty: no input has any triangle");
  return Status::Ok();
}

PackedStream ScenePacker::input_stream() {
  return [this](const PackedBatchFn& fn) -> Status {
    std::vector<PackedTriangle> packed;
    packed.reserve(TriangleBatcher::kBatchSize);
    for (size_t g = 0; g < sources_.size(); ++g) {
      uint32_t next_id = 0;
      const uint64_t expected = scan_.inputs[g].triangle_count;
      auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
        OUTCORE_RETURN_IF_ERROR(check_cancel());
        if (next_id + batch.size() > expected) {
          return failed_precondition("input '" + scan_.inputs[g].spec + "' changed while being packed");
        }
        packed.clear();
        for (const Triangle& t : batch) packed.push_back({t, static_cast<uint32_t>(g), next_id++});
        return fn(packed);
      });
      OUTCORE_RETURN_IF_ERROR(sources_[g]->stream(sink));
      if (next_id != expected) {
        return failed_precondition("input '" + scan_.inputs[g].spec + "' changed while being packed");
      }
    }
    return Status::Ok();
  };
}

Status ScenePacker::write_brick(std::span<const PackedTriangle> triangles, const Aabb& bounds) {
  OUTCORE_RETURN_IF_ERROR(brick_file_.pad_to(kBrickAlignment));
  BrickRecord record;
  record.bounds = bounds;
  record.triangle_count = static_cast<uint32_t>(triangles.size());
  record.offset = brick_file_.size();
  record.size_bytes = brick_total_bytes(triangles.size());
  BrickHeader header{};
  std::memcpy(header.magic, kBrickMagic, sizeof header.magic);
  header.brick_id = static_cast<uint32_t>(bricks_.size());
  header.triangle_count = record.triangle_count;
  header.payload_bytes = brick_payload_bytes(triangles.size());
  Checksum64 checksum;
  checksum.update(&header, sizeof header);
  OUTCORE_RETURN_IF_ERROR(brick_file_.append(&header, sizeof header));
  // Positions, then ids, staged through a fixed buffer so the checksum and the
  // write see large contiguous pieces.
  auto emit = [&](auto&& field_bytes, std::size_t record_bytes) -> Status {
    std::size_t used = 0;
    for (const PackedTriangle& p : triangles) {
      if (used + record_bytes > staging_.size()) {
        checksum.update(staging_.data(), used);
        OUTCORE_RETURN_IF_ERROR(brick_file_.append(staging_.data(), used));
        used = 0;
      }
      field_bytes(p, staging_.data() + used);
      used += record_bytes;
    }
    checksum.update(staging_.data(), used);
    return brick_file_.append(staging_.data(), used);
  };
  OUTCORE_RETURN_IF_ERROR(
      emit([](const PackedTriangle& p, char* out) { std::memcpy(out, &p.tri, sizeof(Triangle)); },
           sizeof(Triangle)));
  OUTCORE_RETURN_IF_ERROR(emit(
      [](const PackedTriangle& p, char* out) {
        std::memcpy(out, &p.geometry_id, sizeof(uint32_t));
        std::memcpy(out + sizeof(uint32_t), &p.primitive_id, sizeof(uint32_t));
      },
      2 * sizeof(uint32_t)));
  record.checksum = checksum.digest();
  bricks_.push_back(record);
  if (brick_progress_) brick_progress_->advance(triangles.size());
  return Status::Ok();
}

Status ScenePacker::build_group_in_memory(const PackedStream& stream, uint64_t count) {
  std::vector<PackedTriangle> triangles;
  triangles.reserve(count);
  {
    PhaseTimer timer(phases_.fill);
    OUTCORE_RETURN_IF_ERROR(stream([&](std::span<const PackedTriangle> batch) -> Status {
      if (triangles.size() + batch.size() > count)
        return internal_error("group holds more triangles than counted");
      triangles.insert(triangles.end(), batch.begin(), batch.end());
      return Status::Ok();
    }));
  }
  if (triangles.size() != count) return internal_error("group holds fewer triangles than counted");
  PhaseTimer timer(phases_.bricks);
  OUTCORE_RETURN_IF_ERROR(check_cancel());
  BrickPartitionerConfig config;
  config.max_triangles = brick_triangles_;
  const std::vector<BrickRange> ranges = partition_into_bricks(triangles, config);
  for (const BrickRange& range : ranges) {
    OUTCORE_RETURN_IF_ERROR(check_cancel());
    OUTCORE_RETURN_IF_ERROR(write_brick(
        std::span<const PackedTriangle>(triangles.data() + range.begin, range.count), range.bounds));
  }
  return Status::Ok();
}

Status ScenePacker::distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                               const GroupFn& group_of, uint32_t depth) {
  const uint32_t group_count = plan.group_count;
  auto recurse = [&](uint32_t g, const SourceStream& group_stream) -> Status {
    // A group that did not shrink cannot be helped by a finer grid.
    if (plan.group_counts[g] == count)
      return pack_sequential_chunks(group_stream, plan.group_counts[g], depth + 1);
    return pack_stream(group_stream, plan.group_counts[g], plan.group_centroid_bounds[g], depth + 1);
  };

  if (source.cheap) {
    // Re-stream the source once per group, keeping that group's triangles:
    // cheaper than a disk round trip for generated scenes.
    for (uint32_t g = 0; g < group_count; ++g) {
      if (plan.group_counts[g] == 0) continue;
      const PackedStream& parent = source.stream;
      SourceStream filtered{[&parent, &group_of, g](const PackedBatchFn& fn) -> Status {
                              std::vector<PackedTriangle> kept;
                              kept.reserve(TriangleBatcher::kBatchSize);
                              uint64_t sequence = 0;
                              return parent([&](std::span<const PackedTriangle> batch) -> Status {
                                kept.clear();
                                for (const PackedTriangle& p : batch) {
                                  if (group_of(p, sequence++) == g) kept.push_back(p);
                                }
                                return kept.empty() ? Status::Ok() : fn(kept);
                              });
                            },
                            true};
      OUTCORE_RETURN_IF_ERROR(recurse(g, filtered));
    }
    return Status::Ok();
  }

  // Spill buffers share a sixteenth of the budget, 64 KiB .. 1 MiB each.
  const uint64_t buffer_bytes = std::clamp<uint64_t>(memory_.spill_buffers / group_count, 64 * 1024, kMiB) /
                                sizeof(PackedTriangle) * sizeof(PackedTriangle);
  std::vector<BufferedFileWriter> writers(group_count);
  std::vector<std::string> paths(group_count);
  std::vector<uint64_t> written(group_count, 0);
  const uint32_t serial = spill_serial_++;
  for (uint32_t g = 0; g < group_count; ++g) {
    paths[g] = temp_.path() + "/spill-" + std::to_string(serial) + "-" + std::to_string(g) + ".bin";
    OUTCORE_RETURN_IF_ERROR(writers[g].create(paths[g], buffer_bytes));
  }
  {
    PhaseTimer timer(phases_.fill);
    ProgressBar bar("distribute", count, "tris", options_.show_progress);
    uint64_t sequence = 0;
    OUTCORE_RETURN_IF_ERROR(source.stream([&](std::span<const PackedTriangle> batch) -> Status {
      for (const PackedTriangle& p : batch) {
        const uint32_t g = group_of(p, sequence++);
        if (g >= group_count) return internal_error("triangle outside every group");
        ++written[g];
        OUTCORE_RETURN_IF_ERROR(writers[g].append(&p, sizeof p));
      }
      bar.advance(batch.size());
      return Status::Ok();
    }));
    bar.finish();
  }
  for (uint32_t g = 0; g < group_count; ++g) {
    if (written[g] != plan.group_counts[g])
      return internal_error("spill counts disagree with the group plan");
    spill_bytes_ += writers[g].size();
    OUTCORE_RETURN_IF_ERROR(writers[g].close(false));
  }
  writers.clear();
  for (uint32_t g = 0; g < group_count; ++g) {
    if (plan.group_counts[g] > 0) {
      const std::string path = paths[g];
      SourceStream spill{
          [path, chunk = memory_.read_chunk](const PackedBatchFn& fn) {
            return read_file_chunks(
                path, sizeof(PackedTriangle), chunk, [&](const char* data, std::size_t bytes) {
                  return fn(std::span<const PackedTriangle>(reinterpret_cast<const PackedTriangle*>(data),
                                                            bytes / sizeof(PackedTriangle)));
                });
          },
          false};
      OUTCORE_RETURN_IF_ERROR(recurse(g, spill));
    }
    std::error_code ec;
    fs::remove(paths[g], ec);
  }
  return Status::Ok();
}

Status ScenePacker::pack_sequential_chunks(const SourceStream& source, uint64_t count, uint32_t depth) {
  const uint64_t chunk = group_capacity_;
  GroupPlan plan;
  plan.group_count = static_cast<uint32_t>((count + chunk - 1) / chunk);
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    plan.group_counts.push_back(std::min(chunk, count - g * chunk));
    plan.group_centroid_bounds.emplace_back();  // unused: chunks fit in memory
  }
  levels_ = std::max(levels_, depth + 1);
  return distribute(
      source, count, plan,
      [chunk](const PackedTriangle&, uint64_t seq) { return static_cast<uint32_t>(seq / chunk); }, depth);
}

Status ScenePacker::pack_stream(const SourceStream& source, uint64_t count, const Aabb& centroid_bounds,
                                uint32_t depth) {
  if (count <= group_capacity_) return build_group_in_memory(source.stream, count);
  levels_ = std::max(levels_, depth + 1);
  if (depth >= kMaxRecursionDepth || centroid_bounds.extent() == Vec3f(0, 0, 0)) {
    return pack_sequential_chunks(source, count, depth);
  }
  const CentroidGrid grid(centroid_bounds, memory_.grid_cells);
  std::vector<CellStats> cells(grid.cell_count());
  {
    PhaseTimer timer(phases_.histogram);
    ProgressBar bar("histogram", count, "tris", options_.show_progress);
    OUTCORE_RETURN_IF_ERROR(source.stream([&](std::span<const PackedTriangle> batch) -> Status {
      OUTCORE_RETURN_IF_ERROR(check_cancel());
      for (const PackedTriangle& p : batch) {
        const Vec3f c = p.tri.centroid();
        CellStats& cell = cells[grid.cell_of(c)];
        ++cell.count;
        cell.bounds.extend(p.tri.bounds());
        cell.centroid_bounds.extend(c);
      }
      bar.advance(batch.size());
      return Status::Ok();
    }));
    bar.finish();
  }
  // Larger groups than fit are fine (they recurse); more than kMaxGroupsPerLevel
  // spill files at once would waste buffers.
  const uint64_t max_group =
      std::max<uint64_t>(group_capacity_, (count + kMaxGroupsPerLevel - 1) / kMaxGroupsPerLevel * 2);
  const GroupPlan plan = plan_groups(grid, cells, max_group);
  cells = {};
  return distribute(
      source, count, plan,
      [&](const PackedTriangle& p, uint64_t) { return plan.cell_to_group[grid.cell_of(p.tri.centroid())]; },
      depth);
}

bool ScenePacker::collect_ranged_generators() {
  generators_.clear();
  for (const auto& source : sources_) {
    const auto* gen = dynamic_cast<const Generator*>(source.get());
    if (gen == nullptr || !gen->has_fast_ranges()) {
      generators_.clear();
      return false;
    }
    generators_.push_back(gen);
  }
  return true;
}

void ScenePacker::make_chunks() {
  uint64_t total = 0;
  for (const Generator* gen : generators_) total += gen->triangle_count();
  // About 1/512 of the budget per chunk (so the filter pipeline's buffers stay
  // small), 16 K .. 128 K triangles, more for scenes beyond kMaxChunks chunks.
  const uint64_t budget = options_.memory_mb * kMiB;
  uint64_t target = std::clamp<uint64_t>(budget / 512 / sizeof(PackedTriangle), 1 << 14, 1 << 17);
  target = std::max(target, (total + kMaxChunks - 1) / kMaxChunks);
  chunks_.clear();
  max_chunk_ = 0;
  for (uint32_t g = 0; g < generators_.size(); ++g) {
    const uint64_t count = generators_[g]->triangle_count();
    const uint64_t step = std::max<uint64_t>(1, generators_[g]->range_granularity());
    // Whole copies/rows when they are not much larger than the target (a
    // partial copy still transforms all of the copy's vertices); otherwise the
    // generator emits partial ones.
    const uint64_t size = step <= target ? target / step * step : (step <= 4 * target ? step : target);
    for (uint64_t first = 0; first < count; first += size) {
      chunks_.push_back({g, first, std::min(count, first + size), Aabb{}});
      max_chunk_ = std::max(max_chunk_, chunks_.back().last - first);
    }
  }
  memory_.chunk_table = chunks_.size() * (sizeof(InputChunk) + sizeof(ChunkScan) + 4 * sizeof(uint32_t));
  memory_.filter_buffers = uint64_t{kFilterTokens} * max_chunk_ * (sizeof(PackedTriangle) + sizeof(uint32_t));
}

// Streams one chunk's triangles to fn(batch, primitive id of batch[0]).
template <class Fn>
Status ScenePacker::generate_chunk(const InputChunk& chunk, Fn&& fn) const {
  uint64_t next = chunk.first;
  const Generator& gen = *generators_[chunk.input];
  auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
    OUTCORE_RETURN_IF_ERROR(check_cancel());
    if (next + batch.size() > chunk.last) {
      return internal_error("input '" + gen.description() + "' emitted more than triangles [" +
                            std::to_string(chunk.first) + ", " + std::to_string(chunk.last) + ")");
    }
    const uint64_t id = next;
    next += batch.size();
    return fn(batch, id);
  });
  // The batch buffer is ~150 KB: keep it off the worker's stack.
  auto batcher = std::make_unique<TriangleBatcher>(sink);
  OUTCORE_RETURN_IF_ERROR(gen.emit_range(chunk.first, chunk.last, *batcher));
  OUTCORE_RETURN_IF_ERROR(batcher->finish());
  if (next != chunk.last) {
    return internal_error("input '" + gen.description() + "' emitted fewer than triangles [" +
                          std::to_string(chunk.first) + ", " + std::to_string(chunk.last) + ")");
  }
  return Status::Ok();
}

// Runs fn(i) for every chunk index on all cores; returns the error of the
// lowest failing index (others stop early).
template <class Fn>
Status parallel_over(std::size_t count, Fn&& fn) {
  std::atomic<bool> failed{false};
  std::mutex mutex;
  std::size_t error_index = count;
  Status error;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        if (failed.load(std::memory_order_relaxed)) return;
                        Status s = fn(i);
                        if (!s.ok()) {
                          std::lock_guard lock(mutex);
                          if (i < error_index) {
                            error_index = i;
                            error = std::move(s);
                          }
                          failed = true;
                        }
                      }
                    });
  return error;
}

Status ScenePacker::scan_chunks() {
  PhaseTimer timer(phases_.scan);
  uint64_t total = 0;
  for (const Generator* gen : generators_) total += gen->triangle_count();
  ProgressBar bar("scan", total, "tris", options_.show_progress);
  std::vector<ChunkScan> results(chunks_.size());
  OUTCORE_RETURN_IF_ERROR(parallel_over(chunks_.size(), [&](std::size_t i) {
    ChunkScan& r = results[i];
    Status s = generate_chunk(chunks_[i], [&](std::span<const Triangle> batch, uint64_t id) -> Status {
      for (std::size_t k = 0; k < batch.size(); ++k) {
        const Triangle& t = batch[k];
        if (const char* problem = vertex_problem(t)) {
          if (id + k < r.first_bad) r.problem = problem;
          r.first_bad = std::min(r.first_bad, id + k);
          continue;
        }
        r.degenerate += t.is_degenerate();
        r.bounds.extend(t.bounds());
        r.centroid_bounds.extend(t.centroid());
      }
      bar.advance(batch.size());
      return Status::Ok();
    });
    chunks_[i].centroid_bounds = r.centroid_bounds;
    return s;
  }));
  bar.finish();
  // Merge in input order; min/max and sums are exact, so any order would do.
  for (uint32_t g = 0; g < generators_.size(); ++g) {
    InputRecord record;
    record.spec = generators_[g]->description();
    record.triangle_count = generators_[g]->triangle_count();
    for (std::size_t i = 0; i < chunks_.size(); ++i) {
      if (chunks_[i].input != g) continue;
      const ChunkScan& r = results[i];
      if (r.first_bad != ~uint64_t{0}) {
        return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "': triangle " +
                                std::to_string(r.first_bad) + " " + r.problem);
      }
      record.degenerate_count += r.degenerate;
      scan_.bounds.extend(r.bounds);
      scan_.centroid_bounds.extend(r.centroid_bounds);
    }
    if (record.triangle_count >= 0xffffffffull) {
      return invalid_argument(
          "input " + std::to_string(g) + " '" + record.spec + "' has " +
          std::to_string(record.triangle_count) +
          " triangles; primitive ids are 32-bit, so an input may hold at most 4294967294");
    }
    scan_.triangles += record.triangle_count;
    scan_.degenerate += record.degenerate_count;
    scan_.inputs.push_back(std::move(record));
  }
  if (scan_.triangles == 0) return invalid_argument("the scene is empty: no input has any triangle");
  return Status::Ok();
}

// Generates the chunks `chunk_ids` on all cores, keeps the triangles for which
// classify(triangle) returns a subgroup (not kNoGroup), and writes them to
// `out`, each subgroup contiguous (in order of sub_counts), in chunk order
// within a subgroup whatever the thread count.
template <class Classify>
Status ScenePacker::fill_group(std::span<const uint32_t> chunk_ids, const Classify& classify,
                               std::span<const uint64_t> sub_counts, PackedTriangle* out) {
  PhaseTimer timer(phases_.fill);
  std::vector<uint64_t> cursor(sub_counts.size());
  uint64_t expected = 0;
  for (std::size_t s = 0; s < sub_counts.size(); ++s) {
    cursor[s] = expected;
    expected += sub_counts[s];
  }
  struct Slot {
    std::vector<PackedTriangle> kept;
    std::vector<uint32_t> sub;
    std::size_t chunk = 0;
    Status status;
  };
  std::vector<Slot> slots(kFilterTokens);
  std::vector<Slot*> free_slots;
  for (Slot& slot : slots) {
    slot.kept.reserve(max_chunk_);
    slot.sub.reserve(max_chunk_);
    free_slots.push_back(&slot);
  }
  std::mutex free_mutex;  // per chunk, not per triangle
  std::size_t next = 0;
  Status error;  // owned by the last (serial) stage
  std::atomic<bool> failed{false};
  uint64_t filled = 0;
  tbb::parallel_pipeline(
      kFilterTokens,
      tbb::make_filter<void, Slot*>(tbb::filter_mode::serial_in_order, [&](tbb::flow_control& fc) -> Slot* {
        if (next == chunk_ids.size() || failed.load()) {
          fc.stop();
          return nullptr;
        }
        std::lock_guard lock(free_mutex);
        Slot* slot = free_slots.back();
        free_slots.pop_back();
        slot->chunk = chunk_ids[next++];
        return slot;
      }) & tbb::make_filter<Slot*, Slot*>(tbb::filter_mode::parallel, [&](Slot* slot) -> Slot* {
        slot->kept.clear();
        slot->sub.clear();
        const InputChunk& chunk = chunks_[slot->chunk];
        slot->status = generate_chunk(chunk, [&](std::span<const Triangle> batch, uint64_t id) -> Status {
          for (std::size_t k = 0; k < batch.size(); ++k) {
            const uint32_t sub = classify(batch[k]);
            if (sub == GroupPlan::kNoGroup) continue;
            slot->kept.push_back({batch[k], chunk.input, static_cast<uint32_t>(id + k)});
            slot->sub.push_back(sub);
          }
          return Status::Ok();
        });
        return slot;
      }) & tbb::make_filter<Slot*, void>(tbb::filter_mode::serial_in_order, [&](Slot* slot) {
        if (error.ok()) {
          error = slot->status;
          if (error.ok() && filled + slot->kept.size() > expected) {
            error = internal_error("group holds more triangles than counted");
          }
          if (error.ok()) {
            for (std::size_t k = 0; k < slot->kept.size(); ++k) out[cursor[slot->sub[k]]++] = slot->kept[k];
            filled += slot->kept.size();
          }
          if (!error.ok()) failed = true;
        }
        std::lock_guard lock(free_mutex);
        free_slots.push_back(slot);
      }));
  OUTCORE_RETURN_IF_ERROR(error);
  if (filled != expected) return internal_error("group holds fewer triangles than counted");
  return Status::Ok();
}

// Partitions each subgroup into bricks on all cores while the bricks of
// earlier subgroups are checksummed and written, in subgroup order.
Status ScenePacker::write_subgroups(PackedTriangle* data, std::span<const uint64_t> sub_counts) {
  PhaseTimer timer(phases_.bricks);
  const double wait_before = brick_file_.wait_seconds();
  std::vector<uint64_t> offsets(sub_counts.size());
  for (std::size_t s = 1; s < sub_counts.size(); ++s) offsets[s] = offsets[s - 1] + sub_counts[s - 1];
  BrickPartitionerConfig config;
  config.max_triangles = brick_triangles_;
  struct Item {
    std::size_t sub;
    std::vector<BrickRange> ranges;
  };
  std::size_t next = 0;
  Status error;  // owned by the last (serial) stage
  std::atomic<bool> failed{false};
  tbb::parallel_pipeline(
      kBrickTokens,
      tbb::make_filter<void, std::shared_ptr<Item>>(tbb::filter_mode::serial_in_order,
                                                    [&](tbb::flow_control& fc) -> std::shared_ptr<Item> {
                                                      while (next < sub_counts.size() &&
                                                             sub_counts[next] == 0)
                                                        ++next;
                                                      if (next == sub_counts.size() || failed.load()) {
                                                        fc.stop();
                                                        return nullptr;
                                                      }
                                                      auto item = std::make_shared<Item>();
                                                      item->sub = next++;
                                                      return item;
                                                    }) &
          tbb::make_filter<std::shared_ptr<Item>, std::shared_ptr<Item>>(
              tbb::filter_mode::parallel,
              [&](std::shared_ptr<Item> item) {
                item->ranges = partition_into_bricks(
                    std::span<PackedTriangle>(data + offsets[item->sub], sub_counts[item->sub]), config);
                return item;
              }) &
          tbb::make_filter<std::shared_ptr<Item>, void>(
              tbb::filter_mode::serial_in_order, [&](const std::shared_ptr<Item>& item) {
                if (!error.ok()) return;
                error = check_cancel();
                const PackedTriangle* base = data + offsets[item->sub];
                for (const BrickRange& r : item->ranges) {
                  if (!error.ok()) break;
                  error = write_brick(std::span<const PackedTriangle>(base + r.begin, r.count), r.bounds);
                }
                if (!error.ok()) failed = true;
              }));
  phases_.write_wait += brick_file_.wait_seconds() - wait_before;
  return error;
}

Status ScenePacker::pack_generated() {
  const uint64_t count = scan_.triangles;
  const uint64_t sub_max =
      std::clamp<uint64_t>(uint64_t{brick_triangles_} * kSubgroupBricks, kMinSubgroupTriangles,
                           std::max<uint64_t>(group_capacity_, 1));
  std::vector<uint32_t> all_chunks(chunks_.size());
  for (uint32_t i = 0; i < all_chunks.size(); ++i) all_chunks[i] = i;

  if (count <= 2 * sub_max || scan_.centroid_bounds.extent() == Vec3f(0, 0, 0)) {
    // No grid can split identical centroids: the general path chunks them.
    if (count > group_capacity_) return pack_stream({input_stream(), true}, count, scan_.centroid_bounds, 0);
    // Small: one group, one subgroup, no grid.
    const std::vector<uint64_t> sub_counts{count};
    OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(count));
    OUTCORE_RETURN_IF_ERROR(fill_group(
        all_chunks, [](const Triangle&) { return uint32_t{0}; }, sub_counts, group_buffer_.data.get()));
    return write_subgroups(group_buffer_.data.get(), sub_counts);
  }

  const CentroidGrid grid(scan_.centroid_bounds, memory_.grid_cells);
  std::vector<CellStats> cells(grid.cell_count());
  {
    PhaseTimer timer(phases_.histogram);
    ProgressBar bar("histogram", count, "tris", options_.show_progress);
    // A fixed number of partial histograms (memory must not depend on the
    // machine), merged exactly (sums, min/max).
    const int copies = std::min(kHistogramCopies, tbb::this_task_arena::max_concurrency());
    std::vector<std::unique_ptr<std::vector<CellStats>>> partial;
    for (int c = 0; c < copies; ++c) partial.push_back(std::make_unique<std::vector<CellStats>>());
    std::vector<int> free_copies;
    for (int c = 0; c < copies; ++c) free_copies.push_back(c);
    std::mutex free_mutex;
    tbb::task_arena arena(copies);
    Status status;
    arena.execute([&] {
      status = parallel_over(chunks_.size(), [&](std::size_t i) {
        std::vector<CellStats>* slot;
        int copy;
        {
          std::lock_guard lock(free_mutex);
          // The arena has `copies` slots, so one is always free; if not, grow.
          if (free_copies.empty()) {
            free_copies.push_back(static_cast<int>(partial.size()));
            partial.push_back(std::make_unique<std::vector<CellStats>>());
          }
          copy = free_copies.back();
          free_copies.pop_back();
          slot = partial[copy].get();
        }
        std::vector<CellStats>& local = *slot;
        if (local.empty()) local.resize(grid.cell_count());
        Status s = generate_chunk(chunks_[i], [&](std::span<const Triangle> batch, uint64_t) -> Status {
          for (const Triangle& t : batch) {
            const Vec3f c = t.centroid();
            CellStats& cell = local[grid.cell_of(c)];
            ++cell.count;
            cell.bounds.extend(t.bounds());
            cell.centroid_bounds.extend(c);
          }
          bar.advance(batch.size());
          return Status::Ok();
        });
        std::lock_guard lock(free_mutex);
        free_copies.push_back(copy);
        return s;
      });
    });
    OUTCORE_RETURN_IF_ERROR(status);
    for (const auto& copy : partial) {
      const std::vector<CellStats>& local = *copy;
      for (std::size_t c = 0; c < local.size(); ++c) {
        cells[c].count += local[c].count;
        cells[c].bounds.extend(local[c].bounds);
        cells[c].centroid_bounds.extend(local[c].centroid_bounds);
      }
    }
    bar.finish();
  }

  const uint64_t max_group =
      count <= group_capacity_
          ? count
          : std::max<uint64_t>(group_capacity_, (count + kMaxGroupsPerLevel - 1) / kMaxGroupsPerLevel * 2);
  const GroupPlan plan = plan_groups(grid, cells, max_group);
  if (plan.group_count > 1) levels_ = std::max(levels_, 1u);

  // Subgroups of every group that fits, planned on that group's cells only.
  std::vector<uint32_t> cell_to_sub(cells.size(), GroupPlan::kNoGroup);
  std::vector<std::vector<uint64_t>> sub_counts(plan.group_count);
  uint64_t largest = 0;
  {
    std::vector<CellStats> masked(cells.size());
    for (uint32_t g = 0; g < plan.group_count; ++g) {
      if (plan.group_counts[g] > group_capacity_) continue;
      largest = std::max(largest, plan.group_counts[g]);
      for (std::size_t c = 0; c < cells.size(); ++c)
        masked[c] = plan.cell_to_group[c] == g ? cells[c] : CellStats{};
      const GroupPlan sub = plan_groups(grid, masked, sub_max, brick_triangles_);
      for (std::size_t c = 0; c < cells.size(); ++c) {
        if (plan.cell_to_group[c] == g) cell_to_sub[c] = sub.cell_to_group[c];
      }
      sub_counts[g] = sub.group_counts;
    }
  }
  cells = {};

  // Which groups each chunk can touch, from its centroid box on the grid.
  std::vector<std::vector<uint32_t>> group_chunks(plan.group_count);
  {
    std::vector<uint32_t> seen(plan.group_count, ~0u);
    const auto& res = grid.resolution();
    for (uint32_t i = 0; i < chunks_.size(); ++i) {
      const Aabb& cb = chunks_[i].centroid_bounds;
      if (cb.empty()) continue;
      const auto lo = grid.cell_coords(cb.lo), hi = grid.cell_coords(cb.hi);
      const uint64_t box = uint64_t{hi[0] - lo[0] + 1} * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
      if (box > kMaxChunkCellsScanned) {
        for (uint32_t g = 0; g < plan.group_count; ++g) group_chunks[g].push_back(i);
        continue;
      }
      for (uint32_t z = lo[2]; z <= hi[2]; ++z)
        for (uint32_t y = lo[1]; y <= hi[1]; ++y)
          for (uint32_t x = lo[0]; x <= hi[0]; ++x) {
            const uint32_t g = plan.cell_to_group[(z * res[1] + y) * res[0] + x];
            if (g != GroupPlan::kNoGroup && seen[g] != i) {
              seen[g] = i;
              group_chunks[g].push_back(i);
            }
          }
    }
  }

  OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(largest));
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    if (plan.group_counts[g] == 0) continue;
    if (plan.group_counts[g] > group_capacity_) {
      // One cell holds more than fits (e.g. many triangles sharing a
      // centroid): the general path filters the inputs to it and recurses.
      group_buffer_ = {};
      const PackedStream parent = input_stream();
      const auto& to_group = plan.cell_to_group;
      SourceStream filtered{[&](const PackedBatchFn& fn) -> Status {
                              std::vector<PackedTriangle> kept;
                              kept.reserve(TriangleBatcher::kBatchSize);
                              return parent([&](std::span<const PackedTriangle> batch) -> Status {
                                kept.clear();
                                for (const PackedTriangle& p : batch) {
                                  if (to_group[grid.cell_of(p.tri.centroid())] == g) kept.push_back(p);
                                }
                                return kept.empty() ? Status::Ok() : fn(kept);
                              });
                            },
                            true};
      OUTCORE_RETURN_IF_ERROR(pack_stream(filtered, plan.group_counts[g], plan.group_centroid_bounds[g], 1));
      continue;
    }
    OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(largest));
    const auto classify = [&grid, &plan, &cell_to_sub, g](const Triangle& t) {
      const uint32_t cell = grid.cell_of(t.centroid());
      return plan.cell_to_group[cell] == g ? cell_to_sub[cell] : GroupPlan::kNoGroup;
    };
    OUTCORE_RETURN_IF_ERROR(fill_group(group_chunks[g], classify, sub_counts[g], group_buffer_.data.get()));
    OUTCORE_RETURN_IF_ERROR(write_subgroups(group_buffer_.data.get(), sub_counts[g]));
  }
  return Status::Ok();
}

Expected<PackSummary> ScenePacker::run() {
  const auto start = std::chrono::steady_clock::now();
  OUTCORE_RETURN_IF_ERROR(validate_options());
  const uint64_t budget = options_.memory_mb * kMiB;
  memory_ = MemoryPlan::for_budget(budget);
  if (options_.vertex_memory_mb > 0) memory_.source_vertices = options_.vertex_memory_mb * kMiB;
  // The temporary directory comes first: file readers that resolve faces out
  // of core keep their spill files in it (each in a directory of its own,
  // removed with its source before the store is renamed into place).
  std::error_code ec;
  const fs::path output_path = normalized_output(options_.output);
  fs::create_directories(output_path.parent_path(), ec);
  remove_stale_partials(output_path);
  OUTCORE_RETURN_IF_ERROR(temp_.create_beside(output_path.string()));
  OUTCORE_RETURN_IF_ERROR(open_sources({memory_.source_vertices, temp_.path()}));
  const bool generated = collect_ranged_generators();
  if (generated) {
    make_chunks();
    // Groups are filtered from regenerated chunks, never spilled; no file inputs.
    memory_.spill_buffers = 0;
    memory_.read_chunk = 0;
    memory_.source_vertices = 0;
  }
  OUTCORE_RETURN_IF_ERROR(generated ? scan_chunks() : scan());

  const uint64_t reserved = memory_.reserved();
  group_capacity_ = budget > reserved ? (budget - reserved) / sizeof(PackedTriangle) : 0;
  if (options_.max_group_triangles > 0)
    group_capacity_ = std::min(group_capacity_, options_.max_group_triangles);
  const auto brick_fits = [&](uint64_t triangles) {
    return triangles * sizeof(PackedTriangle) + reserved <= budget;
  };
  if (options_.brick_triangles.has_value()) {
    brick_triangles_ = *options_.brick_triangles;
  } else {
    // The default: one brick for a small scene (when memory allows it).
    const bool one_brick = scan_.triangles <= kSmallSceneTriangles && brick_fits(scan_.triangles);
    brick_triangles_ =
        one_brick ? static_cast<uint32_t>(std::max<uint64_t>(scan_.triangles, 1)) : kDefaultBrickTriangles;
  }
  group_capacity_ = std::max<uint64_t>(group_capacity_, brick_triangles_);
  if (group_capacity_ < brick_triangles_ || !brick_fits(brick_triangles_)) {
    return invalid_argument("--mem-mb " + std::to_string(options_.memory_mb) +
                            " is too small for bricks of " + std::to_string(brick_triangles_) + " triangles");
  }

  OUTCORE_RETURN_IF_ERROR(brick_file_.create(temp_.path() + "/" + kBrickDataFileName, memory_.brick_buffer,
                                             /*asynchronous=*/true));
  staging_.resize(memory_.staging);

  brick_progress_ = std::make_unique<ProgressBar>("bricks", scan_.triangles, "tris", options_.show_progress);
  bool all_cheap = true;
  for (const auto& source : sources_) all_cheap &= source->cheap_to_restream();
  if (generated) {
    OUTCORE_RETURN_IF_ERROR(pack_generated());
  } else {
    OUTCORE_RETURN_IF_ERROR(
        pack_stream({input_stream(), all_cheap}, scan_.triangles, scan_.centroid_bounds, 0));
  }
  group_buffer_ = {};
  // Readers' spill files go now, so that they never end up in the store.
  sources_.clear();
  generators_.clear();
  brick_progress_->finish();
  const auto finish_start = std::chrono::steady_clock::now();
  OUTCORE_RETURN_IF_ERROR(brick_file_.close(options_.sync));
  OUTCORE_RETURN_IF_ERROR(check_cancel());

  Manifest manifest;
  manifest.format_version = kStoreFormatVersion;
  manifest.outcore_version = OUTCORE_VERSION;
  manifest.brick_triangles_target = brick_triangles_;
  manifest.bounds = scan_.bounds;
  manifest.triangle_count = scan_.triangles;
  manifest.degenerate_count = scan_.degenerate;
  manifest.inputs = scan_.inputs;
  manifest.bricks = std::move(bricks_);
  std::vector<Aabb> brick_bounds;
  brick_bounds.reserve(manifest.bricks.size());
  for (const BrickRecord& b : manifest.bricks) brick_bounds.push_back(b.bounds);
  manifest.upper = build_upper_hierarchy(brick_bounds);
  OUTCORE_RETURN_IF_ERROR(validate_manifest(manifest, options_.output));
  const std::string manifest_path = temp_.path() + "/" + kManifestFileName;
  OUTCORE_RETURN_IF_ERROR(write_manifest(manifest_path, manifest));
  if (options_.sync) {
    const int fd = ::open(manifest_path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::fsync(fd) != 0) {
      if (fd >= 0) ::close(fd);
      return io_error_from_errno("cannot sync " + manifest_path);
    }
    ::close(fd);
    OUTCORE_RETURN_IF_ERROR(sync_directory(temp_.path()));
  }
  OUTCORE_RETURN_IF_ERROR(check_cancel());

  // Swap into place. An existing store is moved aside first and removed only
  // after the new one is in place.
  std::string displaced;
  // Checked again: what is there may have changed while the pack ran.
  OUTCORE_RETURN_IF_ERROR(check_output(output_path));
  if (fs::exists(fs::symlink_status(output_path, ec))) {
    // A leftover of an interrupted run of a process with the same pid must not
    // block the swap.
    const std::string base = output_path.string() + ".replaced-" + std::to_string(::getpid());
    displaced = base;
    for (int attempt = 1; fs::exists(displaced, ec); ++attempt)
      displaced = base + "-" + std::to_string(attempt);
    fs::rename(output_path, displaced, ec);
    if (ec) return io_error("cannot move the existing " + output_path.string() + " aside: " + ec.message());
  }
  fs::rename(temp_.path(), output_path, ec);
  if (ec) {
    if (!displaced.empty()) fs::rename(displaced, output_path, ec);
    return io_error("cannot rename the new store into " + output_path.string() + ": " + ec.message());
  }
  temp_.release();
  if (options_.sync) OUTCORE_RETURN_IF_ERROR(sync_directory(output_path.parent_path().string()));
  if (!displaced.empty()) fs::remove_all(displaced, ec);

  PackSummary summary;
  summary.triangles = manifest.triangle_count;
  summary.degenerate_triangles = manifest.degenerate_count;
  summary.bricks = static_cast<uint32_t>(manifest.bricks.size());
  std::vector<uint32_t> sizes;
  for (const BrickRecord& b : manifest.bricks) sizes.push_back(b.triangle_count);
  std::sort(sizes.begin(), sizes.end());
  summary.brick_triangles_target = brick_triangles_;
  summary.min_brick_triangles = sizes.front();
  summary.median_brick_triangles = sizes[sizes.size() / 2];
  summary.max_brick_triangles = sizes.back();
  summary.upper_depth = manifest.upper.depth();
  summary.bytes_on_disk = fs::file_size(output_path / kBrickDataFileName, ec) +
                          fs::file_size(output_path / kManifestFileName, ec);
  summary.spill_bytes_written = spill_bytes_;
  summary.out_of_core_levels = levels_;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.peak_rss_bytes = peak_rss_bytes();
  summary.phases = phases_;
  summary.phases.finish +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - finish_start).count();
  return summary;
}

}  // namespace

Expected<PackSummary> pack_scene(const PackOptions& options) {
  return ScenePacker(options).run();
}

}  // namespace outcore
