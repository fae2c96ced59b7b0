// pack_scene: turns inputs (OBJ, PLY, gen: specs) into a scene store directory,
// out of core. Peak memory is bounded by PackOptions::memory_mb, not by the
// scene: a scan pass counts and bounds the triangles; scenes that fit are
// partitioned in memory; larger ones are histogrammed on a centroid grid, cut
// into groups that fit (centroid_grid.h), streamed into per-group spill files,
// and each group is partitioned into bricks in memory (brick_partitioner.h),
// recursing with a finer grid where one group is still too large. The fixed
// upper hierarchy is built over the brick bounds at the end.
//
// The store appears atomically: everything is written into a temporary
// directory beside the output, synced, and renamed into place; on any error
// or cancellation (cancellation.h) the temporary directory is removed, and an
// existing store at the output path is never touched unless overwrite is set;
// even then only an Outcore store is replaced, never another file or
// directory, nor one holding an input. Temporary directories left by packs
// that died are removed (and logged) by the next pack to the same output.
//
// Thread-safety: reentrant; uses TBB internally.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

struct PackOptions {
  std::vector<std::string> inputs;  // geometry_id = position in this list
  std::string output;               // the store directory to create
  // Target brick size: no brick holds more triangles than this. Unset (the
  // default): kDefaultBrickTriangles, except that a scene of at most
  // kSmallSceneTriangles triangles is packed as one brick (a brick that
  // small, a few MiB built, gains nothing from being loaded and built in parts,
  // and one brick spares every ray a level of traversal: docs/DESIGN.md).
  std::optional<uint32_t> brick_triangles;
  // Peak memory bound for the packer's own data, in MiB (>= 32).
  uint64_t memory_mb = 1024;
  // Part of memory_mb that OBJ/PLY readers may use for vertex positions, in
  // MiB; 0: an eighth. A file with more vertices resolves its faces out of
  // core (core/io/vertex_spill.h). At most half of memory_mb.
  uint64_t vertex_memory_mb = 0;
  // Replace an existing store at `output` (after the new one is complete).
  bool overwrite = false;
  // An input that yields no triangles is an error (otherwise a warning).
  bool strict = false;
  // fsync the store before the rename (durable against power loss).
  bool sync = true;
  // Progress bars on stderr.
  bool show_progress = false;
  // Cap on the triangles partitioned in memory at once; 0 derives it from
  // memory_mb. Lower values force the out-of-core path (tests, tuning).
  uint64_t max_group_triangles = 0;
};

// Wall seconds per phase. With generated inputs, generation and filtering use
// every core; partitioning overlaps checksumming and writing (bricks), and the
// kernel writes to disk in the background until the final sync (finish).
struct PackPhaseSeconds {
  double scan = 0;        // counts, bounds, degenerates
  double histogram = 0;   // centroid grid counts
  double fill = 0;        // generating/reading triangles into their in-memory groups (and spills)
  double bricks = 0;      // partitioning groups into bricks, checksums, handing bytes to the writer
  double write_wait = 0;  // part of bricks: waiting for the writer because the disk lags
  double finish = 0;      // flush, fsync, manifest, rename
};

struct PackSummary {
  uint64_t triangles = 0;
  uint64_t degenerate_triangles = 0;
  uint32_t bricks = 0;
  uint32_t brick_triangles_target = 0;  // in effect (the option's or the default's)
  uint32_t min_brick_triangles = 0;
  uint32_t median_brick_triangles = 0;
  uint32_t max_brick_triangles = 0;
  uint32_t upper_depth = 0;
  uint64_t bytes_on_disk = 0;
  uint64_t spill_bytes_written = 0;  // temporary data (0 when the scene fit in memory)
  uint32_t out_of_core_levels = 0;   // 0: in memory; 1: one grid pass; more: recursion
  double seconds = 0.0;
  uint64_t peak_rss_bytes = 0;
  PackPhaseSeconds phases;
};

Expected<PackSummary> pack_scene(const PackOptions& options);

// Smallest accepted memory_mb.
inline constexpr uint64_t kMinPackMemoryMb = 32;
// Largest accepted brick size (bricks are built and loaded whole).
inline constexpr uint32_t kMaxBrickTriangles = 1u << 24;
// PackOptions::brick_triangles == 0: bricks of at most this many triangles...
inline constexpr uint32_t kDefaultBrickTriangles = 32768;
// ... unless the whole scene has at most this many: then one brick.
inline constexpr uint64_t kSmallSceneTriangles = 4 * uint64_t{kDefaultBrickTriangles};

}  // namespace outcore
