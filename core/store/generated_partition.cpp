#include "core/store/generated_partition.h"

#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <mutex>
#include <string>
#include <utility>

#include "core/io/triangle_source.h"
#include "core/store/brick_partitioner.h"
#include "core/util/progress.h"

namespace outcore::packing {

namespace {

constexpr uint32_t kBrickTokens = 4;  // subgroups in flight in the brick pipeline
// Per-thread centroid histograms, merged exactly; a fixed number, as memory
// must not depend on the machine.
constexpr int kHistogramCopies = 4;
// A group in memory is cut along grid planes into subgroups of about this many
// bricks, each partitioned on its own: one scatter pass replaces the top
// levels of binary partitioning, and subgroups fit in cache and run in parallel.
constexpr uint64_t kSubgroupBricks = 16;
constexpr uint64_t kMinSubgroupTriangles = 1 << 16;
// A chunk whose centroid box covers more cells than this is assumed to touch
// every group (its cells are not enumerated).
constexpr uint64_t kMaxChunkCellsScanned = 1 << 16;

}  // namespace

Status TriangleBuffer::reserve(uint64_t count) {
  if (count <= capacity) return Status::Ok();
  data.reset();
  data.reset(static_cast<PackedTriangle*>(std::malloc(count * sizeof(PackedTriangle))));
  if (!data) return resource_exhausted("cannot allocate " + std::to_string(count) + " triangles");
  capacity = count;
  return Status::Ok();
}

Status GeneratedPartition::pack(const ScanResult& scan) {
  const uint64_t count = scan.triangles;
  const uint64_t sub_max =
      std::clamp<uint64_t>(uint64_t{context_.brick_triangles} * kSubgroupBricks, kMinSubgroupTriangles,
                           std::max<uint64_t>(context_.group_capacity, 1));
  if (count <= 2 * sub_max || scan.centroid_bounds.extent() == Vec3f(0, 0, 0)) {
    // No grid can split identical centroids: the general path chunks them.
    if (count > context_.group_capacity)
      return general_.pack({inputs_, true}, count, scan.centroid_bounds, 0);
    return pack_one_group(count);
  }
  const CentroidGrid grid(scan.centroid_bounds, context_.memory.grid_cells);
  std::vector<CellStats> cells(grid.cell_count());
  OUTCORE_RETURN_IF_ERROR(histogram(grid, count, cells));
  const uint64_t max_group =
      count <= context_.group_capacity
          ? count
          : std::max<uint64_t>(context_.group_capacity,
                               (count + kMaxGroupsPerLevel - 1) / kMaxGroupsPerLevel * 2);
  GroupLayout layout;
  layout.plan = plan_groups(grid, cells, max_group);
  if (layout.plan.group_count > 1) context_.levels = std::max(context_.levels, 1u);
  plan_subgroups(grid, cells, sub_max, layout);
  cells = {};
  find_group_chunks(grid, layout);

  const GroupPlan& plan = layout.plan;
  OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(layout.largest));
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    if (plan.group_counts[g] == 0) continue;
    if (plan.group_counts[g] > context_.group_capacity) {
      OUTCORE_RETURN_IF_ERROR(pack_oversized_group(grid, plan, g));
      continue;
    }
    OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(layout.largest));
    const auto classify = [&grid, &plan, &layout, g](const Triangle& t) {
      const uint32_t cell = grid.cell_of(t.centroid());
      return plan.cell_to_group[cell] == g ? layout.cell_to_sub[cell] : GroupPlan::kNoGroup;
    };
    OUTCORE_RETURN_IF_ERROR(
        fill_group(layout.group_chunks[g], classify, layout.sub_counts[g], group_buffer_.data.get()));
    OUTCORE_RETURN_IF_ERROR(write_subgroups(group_buffer_.data.get(), layout.sub_counts[g]));
  }
  return Status::Ok();
}

Status GeneratedPartition::pack_one_group(uint64_t count) {
  // Small: one group, one subgroup, no grid.
  std::vector<uint32_t> all_chunks(chunks_.chunks().size());
  for (uint32_t i = 0; i < all_chunks.size(); ++i) all_chunks[i] = i;
  const std::vector<uint64_t> sub_counts{count};
  OUTCORE_RETURN_IF_ERROR(group_buffer_.reserve(count));
  OUTCORE_RETURN_IF_ERROR(fill_group(
      all_chunks, [](const Triangle&) { return uint32_t{0}; }, sub_counts, group_buffer_.data.get()));
  return write_subgroups(group_buffer_.data.get(), sub_counts);
}

Status GeneratedPartition::histogram(const CentroidGrid& grid, uint64_t count,
                                     std::vector<CellStats>& cells) const {
  PhaseTimer timer(context_.phases.histogram);
  ProgressBar bar("histogram", count, "tris", context_.options.show_progress);
  const int copies = std::min(kHistogramCopies, tbb::this_task_arena::max_concurrency());
  std::vector<std::unique_ptr<std::vector<CellStats>>> partial;
  for (int c = 0; c < copies; ++c) partial.push_back(std::make_unique<std::vector<CellStats>>());
  std::vector<int> free_copies;
  for (int c = 0; c < copies; ++c) free_copies.push_back(c);
  std::mutex free_mutex;
  // Takes a free partial histogram; the arena has `copies` slots, so one is
  // always free; if not, grow.
  const auto take_copy = [&]() {
    std::lock_guard lock(free_mutex);
    if (free_copies.empty()) {
      free_copies.push_back(static_cast<int>(partial.size()));
      partial.push_back(std::make_unique<std::vector<CellStats>>());
    }
    const int copy = free_copies.back();
    free_copies.pop_back();
    return std::pair<int, std::vector<CellStats>*>(copy, partial[copy].get());
  };
  tbb::task_arena arena(copies);
  Status status;
  arena.execute([&] {
    status = parallel_over(chunks_.chunks().size(), [&](std::size_t i) {
      const auto [copy, slot] = take_copy();
      std::vector<CellStats>& local = *slot;
      if (local.empty()) local.resize(grid.cell_count());
      Status s =
          chunks_.generate(chunks_.chunks()[i], [&](std::span<const Triangle> batch, uint64_t) -> Status {
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
  // Sums and min/max: exact in any order.
  for (const auto& copy : partial) {
    const std::vector<CellStats>& local = *copy;
    for (std::size_t c = 0; c < local.size(); ++c) {
      cells[c].count += local[c].count;
      cells[c].bounds.extend(local[c].bounds);
      cells[c].centroid_bounds.extend(local[c].centroid_bounds);
    }
  }
  bar.finish();
  return Status::Ok();
}

void GeneratedPartition::plan_subgroups(const CentroidGrid& grid, const std::vector<CellStats>& cells,
                                        uint64_t sub_max, GroupLayout& layout) const {
  // Subgroups of every group that fits, planned on that group's cells only.
  const GroupPlan& plan = layout.plan;
  layout.cell_to_sub.assign(cells.size(), GroupPlan::kNoGroup);
  layout.sub_counts.assign(plan.group_count, {});
  std::vector<CellStats> masked(cells.size());
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    if (plan.group_counts[g] > context_.group_capacity) continue;
    layout.largest = std::max(layout.largest, plan.group_counts[g]);
    for (std::size_t c = 0; c < cells.size(); ++c)
      masked[c] = plan.cell_to_group[c] == g ? cells[c] : CellStats{};
    const GroupPlan sub = plan_groups(grid, masked, sub_max, context_.brick_triangles);
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (plan.cell_to_group[c] == g) layout.cell_to_sub[c] = sub.cell_to_group[c];
    }
    layout.sub_counts[g] = sub.group_counts;
  }
}

void GeneratedPartition::find_group_chunks(const CentroidGrid& grid, GroupLayout& layout) const {
  // Which groups each chunk can touch, from its centroid box on the grid.
  const GroupPlan& plan = layout.plan;
  layout.group_chunks.assign(plan.group_count, {});
  std::vector<uint32_t> seen(plan.group_count, ~0u);
  const auto& res = grid.resolution();
  const std::vector<InputChunk>& chunks = chunks_.chunks();
  for (uint32_t i = 0; i < chunks.size(); ++i) {
    const Aabb& cb = chunks[i].centroid_bounds;
    if (cb.empty()) continue;
    const auto lo = grid.cell_coords(cb.lo), hi = grid.cell_coords(cb.hi);
    const uint64_t box = uint64_t{hi[0] - lo[0] + 1} * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
    if (box > kMaxChunkCellsScanned) {
      for (uint32_t g = 0; g < plan.group_count; ++g) layout.group_chunks[g].push_back(i);
      continue;
    }
    for (uint32_t z = lo[2]; z <= hi[2]; ++z)
      for (uint32_t y = lo[1]; y <= hi[1]; ++y)
        for (uint32_t x = lo[0]; x <= hi[0]; ++x) {
          const uint32_t g = plan.cell_to_group[(z * res[1] + y) * res[0] + x];
          if (g != GroupPlan::kNoGroup && seen[g] != i) {
            seen[g] = i;
            layout.group_chunks[g].push_back(i);
          }
        }
  }
}

Status GeneratedPartition::pack_oversized_group(const CentroidGrid& grid, const GroupPlan& plan, uint32_t g) {
  // One cell holds more than fits (e.g. many triangles sharing a centroid):
  // the general path filters the inputs to it and recurses.
  group_buffer_ = {};
  const PackedStream& parent = inputs_;
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
  return general_.pack(filtered, plan.group_counts[g], plan.group_centroid_bounds[g], 1);
}

// Generates the chunks `chunk_ids` on all cores, keeps the triangles for which
// classify(triangle) returns a subgroup (not kNoGroup), and writes them to
// `out`, each subgroup contiguous (in order of sub_counts), in chunk order
// within a subgroup whatever the thread count.
template <class Classify>
Status GeneratedPartition::fill_group(std::span<const uint32_t> chunk_ids, const Classify& classify,
                                      std::span<const uint64_t> sub_counts, PackedTriangle* out) {
  PhaseTimer timer(context_.phases.fill);
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
    slot.kept.reserve(chunks_.max_chunk_triangles());
    slot.sub.reserve(chunks_.max_chunk_triangles());
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
        const InputChunk& chunk = chunks_.chunks()[slot->chunk];
        slot->status = chunks_.generate(chunk, [&](std::span<const Triangle> batch, uint64_t id) -> Status {
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
Status GeneratedPartition::write_subgroups(PackedTriangle* data, std::span<const uint64_t> sub_counts) {
  PhaseTimer timer(context_.phases.bricks);
  const double wait_before = bricks_.wait_seconds();
  std::vector<uint64_t> offsets(sub_counts.size());
  for (std::size_t s = 1; s < sub_counts.size(); ++s) offsets[s] = offsets[s - 1] + sub_counts[s - 1];
  BrickPartitionerConfig config;
  config.max_triangles = context_.brick_triangles;
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
                error = context_.check_cancel();
                const PackedTriangle* base = data + offsets[item->sub];
                for (const BrickRange& r : item->ranges) {
                  if (!error.ok()) break;
                  error = bricks_.write(std::span<const PackedTriangle>(base + r.begin, r.count), r.bounds);
                }
                if (!error.ok()) failed = true;
              }));
  context_.phases.write_wait += bricks_.wait_seconds() - wait_before;
  return error;
}

}  // namespace outcore::packing
