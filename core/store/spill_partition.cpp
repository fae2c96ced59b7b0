#include "core/store/spill_partition.h"

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"
#include "core/store/brick_partitioner.h"
#include "core/util/buffered_file.h"
#include "core/util/progress.h"

namespace outcore::packing {

Status SpillPartition::build_group_in_memory(const PackedStream& stream, uint64_t count) {
  std::vector<PackedTriangle> triangles;
  triangles.reserve(count);
  {
    PhaseTimer timer(context_.phases.fill);
    OUTCORE_RETURN_IF_ERROR(stream([&](std::span<const PackedTriangle> batch) -> Status {
      if (triangles.size() + batch.size() > count)
        return internal_error("group holds more triangles than counted");
      triangles.insert(triangles.end(), batch.begin(), batch.end());
      return Status::Ok();
    }));
  }
  if (triangles.size() != count) return internal_error("group holds fewer triangles than counted");
  PhaseTimer timer(context_.phases.bricks);
  OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
  BrickPartitionerConfig config;
  config.max_triangles = context_.brick_triangles;
  const std::vector<BrickRange> ranges = partition_into_bricks(triangles, config);
  for (const BrickRange& range : ranges) {
    OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
    OUTCORE_RETURN_IF_ERROR(bricks_.write(
        std::span<const PackedTriangle>(triangles.data() + range.begin, range.count), range.bounds));
  }
  return Status::Ok();
}

Status SpillPartition::pack_group(const SourceStream& group_stream, uint64_t count, const GroupPlan& plan,
                                  uint32_t g, uint32_t depth) {
  // A group that did not shrink cannot be helped by a finer grid.
  if (plan.group_counts[g] == count)
    return pack_sequential_chunks(group_stream, plan.group_counts[g], depth + 1);
  return pack(group_stream, plan.group_counts[g], plan.group_centroid_bounds[g], depth + 1);
}

Status SpillPartition::distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                                  const GroupFn& group_of, uint32_t depth) {
  return source.cheap ? restream_groups(source, count, plan, group_of, depth)
                      : spill_groups(source, count, plan, group_of, depth);
}

Status SpillPartition::restream_groups(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                                       const GroupFn& group_of, uint32_t depth) {
  // Re-stream the source once per group, keeping that group's triangles:
  // cheaper than a disk round trip for generated scenes.
  for (uint32_t g = 0; g < plan.group_count; ++g) {
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
    OUTCORE_RETURN_IF_ERROR(pack_group(filtered, count, plan, g, depth));
  }
  return Status::Ok();
}

Status SpillPartition::spill_groups(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                                    const GroupFn& group_of, uint32_t depth) {
  const uint32_t group_count = plan.group_count;
  // Spill buffers share a sixteenth of the budget, 64 KiB .. 1 MiB each.
  const uint64_t buffer_bytes =
      std::clamp<uint64_t>(context_.memory.spill_buffers / group_count, 64 * 1024, kMiB) /
      sizeof(PackedTriangle) * sizeof(PackedTriangle);
  std::vector<BufferedFileWriter> writers(group_count);
  std::vector<std::string> paths(group_count);
  std::vector<uint64_t> written(group_count, 0);
  const uint32_t serial = spill_serial_++;
  for (uint32_t g = 0; g < group_count; ++g) {
    paths[g] = context_.temp_dir + "/spill-" + std::to_string(serial) + "-" + std::to_string(g) + ".bin";
    OUTCORE_RETURN_IF_ERROR(writers[g].create(paths[g], buffer_bytes));
  }
  {
    PhaseTimer timer(context_.phases.fill);
    ProgressBar bar("distribute", count, "tris", context_.options.show_progress);
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
    context_.spill_bytes += writers[g].size();
    OUTCORE_RETURN_IF_ERROR(writers[g].close(false));
  }
  writers.clear();
  for (uint32_t g = 0; g < group_count; ++g) {
    if (plan.group_counts[g] > 0) {
      const std::string path = paths[g];
      SourceStream spill{
          [path, chunk = context_.memory.read_chunk](const PackedBatchFn& fn) {
            return read_file_chunks(
                path, sizeof(PackedTriangle), chunk, [&](const char* data, std::size_t bytes) {
                  return fn(std::span<const PackedTriangle>(reinterpret_cast<const PackedTriangle*>(data),
                                                            bytes / sizeof(PackedTriangle)));
                });
          },
          false};
      OUTCORE_RETURN_IF_ERROR(pack_group(spill, count, plan, g, depth));
    }
    std::error_code ec;
    std::filesystem::remove(paths[g], ec);
  }
  return Status::Ok();
}

Status SpillPartition::pack_sequential_chunks(const SourceStream& source, uint64_t count, uint32_t depth) {
  const uint64_t chunk = context_.group_capacity;
  GroupPlan plan;
  plan.group_count = static_cast<uint32_t>((count + chunk - 1) / chunk);
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    plan.group_counts.push_back(std::min(chunk, count - g * chunk));
    plan.group_centroid_bounds.emplace_back();  // unused: chunks fit in memory
  }
  context_.levels = std::max(context_.levels, depth + 1);
  return distribute(
      source, count, plan,
      [chunk](const PackedTriangle&, uint64_t seq) { return static_cast<uint32_t>(seq / chunk); }, depth);
}

Status SpillPartition::histogram(const SourceStream& source, uint64_t count, const CentroidGrid& grid,
                                 std::vector<CellStats>& cells) {
  PhaseTimer timer(context_.phases.histogram);
  ProgressBar bar("histogram", count, "tris", context_.options.show_progress);
  OUTCORE_RETURN_IF_ERROR(source.stream([&](std::span<const PackedTriangle> batch) -> Status {
    OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
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
  return Status::Ok();
}

Status SpillPartition::pack(const SourceStream& source, uint64_t count, const Aabb& centroid_bounds,
                            uint32_t depth) {
  if (count <= context_.group_capacity) return build_group_in_memory(source.stream, count);
  context_.levels = std::max(context_.levels, depth + 1);
  if (depth >= kMaxRecursionDepth || centroid_bounds.extent() == Vec3f(0, 0, 0)) {
    return pack_sequential_chunks(source, count, depth);
  }
  const CentroidGrid grid(centroid_bounds, context_.memory.grid_cells);
  std::vector<CellStats> cells(grid.cell_count());
  OUTCORE_RETURN_IF_ERROR(histogram(source, count, grid, cells));
  const uint64_t max_group =
      std::max<uint64_t>(context_.group_capacity, (count + kMaxGroupsPerLevel - 1) / kMaxGroupsPerLevel * 2);
  const GroupPlan plan = plan_groups(grid, cells, max_group);
  cells = {};
  return distribute(
      source, count, plan,
      [&](const PackedTriangle& p, uint64_t) { return plan.cell_to_group[grid.cell_of(p.tri.centroid())]; },
      depth);
}

}  // namespace outcore::packing
