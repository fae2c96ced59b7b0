#include "core/store/scene_packer.h"

#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>

#include "core/io/source_factory.h"
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

namespace outcore {

namespace {

namespace fs = std::filesystem;

constexpr uint64_t kMiB = 1024 * 1024;
// How the memory bound is shared: fixed-size helpers scale with the budget so
// that small budgets still leave most of it for the in-memory triangle group.
struct MemoryPlan {
  uint32_t grid_cells;        // centroid grid: 1/16 of the budget, 4 K .. 256 K cells
  uint64_t brick_buffer;      // two of them: the brick file writes asynchronously
  uint64_t staging;           // brick payload staging
  uint64_t read_chunk;        // spill reads
  uint64_t spill_buffers;     // shared by all spill writers of one level
  uint64_t batches = 4 * kMiB;  // source and packed batches, filters
  uint64_t reserved() const {
    return uint64_t{grid_cells} * (sizeof(CellStats) + sizeof(uint32_t)) + 2 * brick_buffer + staging +
           2 * read_chunk + spill_buffers + batches;
  }
  static MemoryPlan for_budget(uint64_t budget) {
    MemoryPlan plan{};
    plan.grid_cells =
        static_cast<uint32_t>(std::clamp<uint64_t>(budget / 16 / (sizeof(CellStats) + sizeof(uint32_t)), 1u << 12, 1u << 18));
    plan.brick_buffer = std::clamp<uint64_t>(budget / 64, 256 * 1024, 4 * kMiB);
    plan.staging = std::clamp<uint64_t>(budget / 128, 64 * 1024, kMiB);
    plan.read_chunk = std::clamp<uint64_t>(budget / 64, 256 * 1024, 4 * kMiB);
    plan.spill_buffers = budget / 16;
    return plan;
  }
};
constexpr uint32_t kMaxGroupsPerLevel = 256;
constexpr uint32_t kMaxRecursionDepth = 16;

using PackedBatchFn = std::function<Status(std::span<const PackedTriangle>)>;
// A re-streamable set of tagged triangles: the inputs themselves or a spill file.
using PackedStream = std::function<Status(const PackedBatchFn&)>;
struct SourceStream {
  PackedStream stream;
  bool cheap = false;  // re-streaming beats a spill round trip
};
// Which group a triangle (and its position in the stream) belongs to.
using GroupFn = std::function<uint32_t(const PackedTriangle&, uint64_t)>;

// Removes the temporary directory unless the pack succeeded.
class TemporaryDirectory {
 public:
  ~TemporaryDirectory() {
    if (!path_.empty()) {
      std::error_code ec;
      fs::remove_all(path_, ec);
    }
  }
  Status create_beside(const std::string& output) {
    std::string pattern = output + ".partial-XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) return io_error_from_errno("cannot create a temporary directory beside " + output);
    path_ = pattern;
    return Status::Ok();
  }
  const std::string& path() const { return path_; }
  void release() { path_.clear(); }

 private:
  std::string path_;
};

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
  Status open_sources();
  Status scan();
  PackedStream input_stream();
  Status pack_stream(const SourceStream& source, uint64_t count, const Aabb& centroid_bounds, uint32_t depth);
  Status pack_sequential_chunks(const SourceStream& source, uint64_t count, uint32_t depth);
  Status distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan, const GroupFn& group_of,
                    uint32_t depth);
  Status build_group_in_memory(const PackedStream& stream, uint64_t count);
  Status write_brick(std::span<const PackedTriangle> triangles, const Aabb& bounds);
  Status check_cancel() const { return cancel_requested() ? cancelled("pack interrupted") : Status::Ok(); }

  const PackOptions& options_;
  std::vector<std::unique_ptr<TriangleSource>> sources_;
  ScanResult scan_;
  MemoryPlan memory_{};
  uint64_t group_capacity_ = 0;  // triangles that fit in memory at once
  TemporaryDirectory temp_;
  BufferedFileWriter brick_file_;
  std::vector<char> staging_;
  std::vector<BrickRecord> bricks_;
  std::unique_ptr<ProgressBar> brick_progress_;
  uint64_t spill_bytes_ = 0;
  uint32_t levels_ = 0;
  uint32_t spill_serial_ = 0;
};

Status ScenePacker::validate_options() const {
  if (options_.inputs.empty()) return invalid_argument("no inputs given");
  if (options_.output.empty()) return invalid_argument("no output store given (-o)");
  if (options_.brick_triangles == 0 || options_.brick_triangles > kMaxBrickTriangles) {
    return invalid_argument("--brick-tris must be between 1 and " + std::to_string(kMaxBrickTriangles) + ", got " +
                            std::to_string(options_.brick_triangles));
  }
  if (options_.memory_mb < kMinPackMemoryMb) {
    return invalid_argument("--mem-mb must be at least " + std::to_string(kMinPackMemoryMb) + ", got " +
                            std::to_string(options_.memory_mb));
  }
  if (options_.inputs.size() >= 0xffffffffull) return invalid_argument("too many inputs");
  std::error_code ec;
  if (fs::exists(options_.output, ec) && !options_.overwrite) {
    return already_exists("output " + options_.output + " already exists (use --force to replace it)");
  }
  return Status::Ok();
}

Status ScenePacker::open_sources() {
  for (const std::string& spec : options_.inputs) {
    auto source = open_triangle_source(spec);
    if (!source.ok()) return source.status();
    sources_.push_back(std::move(source).value());
  }
  return Status::Ok();
}

Status ScenePacker::scan() {
  ProgressBar bar("scan", 0, "tris", options_.show_progress);
  for (size_t g = 0; g < sources_.size(); ++g) {
    InputRecord record;
    record.spec = sources_[g]->description();
    auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
      OUTCORE_RETURN_IF_ERROR(check_cancel());
      for (const Triangle& t : batch) {
        if (!t.is_finite()) {
          return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "': triangle " +
                                  std::to_string(record.triangle_count) + " has a NaN or infinite coordinate");
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
      return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "' has " +
                              std::to_string(record.triangle_count) +
                              " triangles; primitive ids are 32-bit, so an input may hold at most 4294967294");
    }
    scan_.triangles += record.triangle_count;
    scan_.degenerate += record.degenerate_count;
    scan_.inputs.push_back(std::move(record));
  }
  bar.finish();
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
  OUTCORE_RETURN_IF_ERROR(emit([](const PackedTriangle& p, char* out) { std::memcpy(out, &p.tri, sizeof(Triangle)); },
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
  OUTCORE_RETURN_IF_ERROR(stream([&](std::span<const PackedTriangle> batch) -> Status {
    if (triangles.size() + batch.size() > count) return internal_error("group holds more triangles than counted");
    triangles.insert(triangles.end(), batch.begin(), batch.end());
    return Status::Ok();
  }));
  if (triangles.size() != count) return internal_error("group holds fewer triangles than counted");
  OUTCORE_RETURN_IF_ERROR(check_cancel());
  BrickPartitionerConfig config;
  config.max_triangles = options_.brick_triangles;
  const std::vector<BrickRange> ranges = partition_into_bricks(triangles, config);
  for (const BrickRange& range : ranges) {
    OUTCORE_RETURN_IF_ERROR(check_cancel());
    OUTCORE_RETURN_IF_ERROR(
        write_brick(std::span<const PackedTriangle>(triangles.data() + range.begin, range.count), range.bounds));
  }
  return Status::Ok();
}

Status ScenePacker::distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                               const GroupFn& group_of, uint32_t depth) {
  const uint32_t group_count = plan.group_count;
  auto recurse = [&](uint32_t g, const SourceStream& group_stream) -> Status {
    // A group that did not shrink cannot be helped by a finer grid.
    if (plan.group_counts[g] == count) return pack_sequential_chunks(group_stream, plan.group_counts[g], depth + 1);
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
  const uint64_t buffer_bytes =
      std::clamp<uint64_t>(memory_.spill_buffers / group_count, 64 * 1024, kMiB) / sizeof(PackedTriangle) *
      sizeof(PackedTriangle);
  std::vector<BufferedFileWriter> writers(group_count);
  std::vector<std::string> paths(group_count);
  std::vector<uint64_t> written(group_count, 0);
  const uint32_t serial = spill_serial_++;
  for (uint32_t g = 0; g < group_count; ++g) {
    paths[g] = temp_.path() + "/spill-" + std::to_string(serial) + "-" + std::to_string(g) + ".bin";
    OUTCORE_RETURN_IF_ERROR(writers[g].create(paths[g], buffer_bytes));
  }
  {
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
    if (written[g] != plan.group_counts[g]) return internal_error("spill counts disagree with the group plan");
    spill_bytes_ += writers[g].size();
    OUTCORE_RETURN_IF_ERROR(writers[g].close(false));
  }
  writers.clear();
  for (uint32_t g = 0; g < group_count; ++g) {
    if (plan.group_counts[g] > 0) {
      const std::string path = paths[g];
      SourceStream spill{[path, chunk = memory_.read_chunk](const PackedBatchFn& fn) {
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
  return distribute(source, count, plan, [chunk](const PackedTriangle&, uint64_t seq) {
    return static_cast<uint32_t>(seq / chunk);
  }, depth);
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
  const uint64_t max_group = std::max<uint64_t>(group_capacity_, (count + kMaxGroupsPerLevel - 1) / kMaxGroupsPerLevel * 2);
  const GroupPlan plan = plan_groups(grid, cells, max_group);
  cells = {};
  return distribute(source, count, plan, [&](const PackedTriangle& p, uint64_t) {
    return plan.cell_to_group[grid.cell_of(p.tri.centroid())];
  }, depth);
}

Expected<PackSummary> ScenePacker::run() {
  const auto start = std::chrono::steady_clock::now();
  OUTCORE_RETURN_IF_ERROR(validate_options());
  OUTCORE_RETURN_IF_ERROR(open_sources());
  OUTCORE_RETURN_IF_ERROR(scan());

  const uint64_t budget = options_.memory_mb * kMiB;
  memory_ = MemoryPlan::for_budget(budget);
  const uint64_t reserved = memory_.reserved();
  group_capacity_ = budget > reserved ? (budget - reserved) / sizeof(PackedTriangle) : 0;
  if (options_.max_group_triangles > 0) group_capacity_ = std::min(group_capacity_, options_.max_group_triangles);
  group_capacity_ = std::max<uint64_t>(group_capacity_, options_.brick_triangles);
  if (group_capacity_ < options_.brick_triangles ||
      static_cast<uint64_t>(options_.brick_triangles) * sizeof(PackedTriangle) + reserved > budget) {
    return invalid_argument("--mem-mb " + std::to_string(options_.memory_mb) + " is too small for bricks of " +
                            std::to_string(options_.brick_triangles) + " triangles");
  }

  std::error_code ec;
  const fs::path output_path = fs::absolute(options_.output, ec);
  fs::create_directories(output_path.parent_path(), ec);
  OUTCORE_RETURN_IF_ERROR(temp_.create_beside(output_path.string()));
  OUTCORE_RETURN_IF_ERROR(brick_file_.create(temp_.path() + "/" + kBrickDataFileName, memory_.brick_buffer, /*asynchronous=*/true));
  staging_.resize(memory_.staging);

  brick_progress_ = std::make_unique<ProgressBar>("bricks", scan_.triangles, "tris", options_.show_progress);
  bool all_cheap = true;
  for (const auto& source : sources_) all_cheap &= source->cheap_to_restream();
  OUTCORE_RETURN_IF_ERROR(pack_stream({input_stream(), all_cheap}, scan_.triangles, scan_.centroid_bounds, 0));
  brick_progress_->finish();
  OUTCORE_RETURN_IF_ERROR(brick_file_.close(options_.sync));
  OUTCORE_RETURN_IF_ERROR(check_cancel());

  Manifest manifest;
  manifest.format_version = kStoreFormatVersion;
  manifest.outcore_version = OUTCORE_VERSION;
  manifest.brick_triangles_target = options_.brick_triangles;
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
  if (fs::exists(output_path, ec)) {
    displaced = output_path.string() + ".replaced-" + std::to_string(::getpid());
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
  summary.min_brick_triangles = sizes.front();
  summary.median_brick_triangles = sizes[sizes.size() / 2];
  summary.max_brick_triangles = sizes.back();
  summary.upper_depth = manifest.upper.depth();
  summary.bytes_on_disk = fs::file_size(output_path / kBrickDataFileName, ec) + fs::file_size(output_path / kManifestFileName, ec);
  summary.spill_bytes_written = spill_bytes_;
  summary.out_of_core_levels = levels_;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.peak_rss_bytes = peak_rss_bytes();
  return summary;
}

}  // namespace

Expected<PackSummary> pack_scene(const PackOptions& options) { return ScenePacker(options).run(); }

}  // namespace outcore
