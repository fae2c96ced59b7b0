// BrickWriter: appends bricks to the store's brick file being built, each at
// kBrickAlignment with its header, positions, then ids, checksummed as
// written, and keeps the manifest's record of every brick. The file writes
// asynchronously (two buffers), so partitioning overlaps the disk.
//
// Thread-safety: one thread at a time (the brick pipelines call it from their
// serial stage).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/store/manifest.h"
#include "core/util/buffered_file.h"
#include "core/util/progress.h"
#include "core/util/status.h"

namespace outcore::packing {

class BrickWriter {
 public:
  // Creates the brick file at `path` with buffers of `buffer_bytes` and a
  // staging buffer of `staging_bytes`; a progress bar counts `triangles`.
  Status create(const std::string& path, uint64_t buffer_bytes, uint64_t staging_bytes, uint64_t triangles,
                bool show_progress);
  // Appends one brick of `triangles` (in this order) bounded by `bounds`.
  Status write(std::span<const PackedTriangle> triangles, const Aabb& bounds);
  // Seconds spent waiting for the disk so far.
  double wait_seconds() const { return file_.wait_seconds(); }
  // Finishes the progress bar, flushes and closes the file (fsync when `sync`).
  Status close(bool sync);
  // The bricks written, in file order.
  std::vector<BrickRecord> take_bricks() { return std::move(bricks_); }

 private:
  BufferedFileWriter file_;
  std::vector<char> staging_;
  std::vector<BrickRecord> bricks_;
  // One brick's triangles for fitting its sphere and oriented box (reused:
  // at most the largest brick, 36 B a triangle, next to the 44 B a triangle
  // the pipeline already holds for it).
  std::vector<Triangle> bound_scratch_;
  std::unique_ptr<ProgressBar> progress_;
};

}  // namespace outcore::packing
