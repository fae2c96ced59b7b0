// MemoryPlan: how the packer shares its --mem-mb bound between fixed-size
// helpers (centroid grid, brick and spill buffers, reader vertices, the
// generated path's chunk table and filter buffers) and the in-memory triangle
// group, which gets what is left. Helpers scale with the budget so that small
// budgets still leave most of it for the group. Nothing here may depend on the
// machine (thread count): the plan decides the bricks, which must not.
//
// Thread-safety: a plain value.
#pragma once

#include <algorithm>
#include <cstdint>

#include "core/store/centroid_grid.h"

namespace outcore::packing {

inline constexpr uint64_t kMiB = 1024 * 1024;

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
  // Generated inputs only (generated_partition.h): the chunk table, the filter
  // pipeline's per-token chunk buffers, and each cell's subgroup.
  uint64_t chunk_table = 0;
  uint64_t filter_buffers = 0;
  // Meshes inputs hold for their lifetime (gen:city's base, an .npz file's
  // mesh), at most half of the budget (PackInputs::open).
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

// Larger groups than fit are fine (they recurse); more groups than this per
// level would open as many spill files at once and waste buffers.
inline constexpr uint32_t kMaxGroupsPerLevel = 256;
inline constexpr uint32_t kMaxRecursionDepth = 16;

}  // namespace outcore::packing
