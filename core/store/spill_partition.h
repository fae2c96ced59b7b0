// SpillPartition: the general (file) path that cuts a stream of triangles
// into bricks within the memory bound. A stream that fits is partitioned in
// memory (brick_partitioner.h); a larger one is histogrammed on a centroid
// grid, cut into groups that fit (centroid_grid.h) and each group handled
// again: re-streamed and filtered when the source is cheap to stream
// (generators), else spilled to one file per group in the temporary store
// directory and read back. A group that does not shrink, or identical
// centroids, fall back to cutting the stream into sequential chunks.
//
// Thread-safety: one thread at a time.
#pragma once

#include <cstdint>
#include <functional>

#include "core/store/brick_writer.h"
#include "core/store/centroid_grid.h"
#include "core/store/pack_context.h"

namespace outcore::packing {

class SpillPartition {
 public:
  SpillPartition(PackContext& context, BrickWriter& bricks) : context_(context), bricks_(bricks) {}

  // Packs the `count` triangles of `source` whose centroids lie in
  // `centroid_bounds`; `depth` is the out-of-core level (0 for the inputs).
  Status pack(const SourceStream& source, uint64_t count, const Aabb& centroid_bounds, uint32_t depth);

 private:
  // Which group a triangle (and its position in the stream) belongs to.
  using GroupFn = std::function<uint32_t(const PackedTriangle&, uint64_t)>;

  Status pack_sequential_chunks(const SourceStream& source, uint64_t count, uint32_t depth);
  Status histogram(const SourceStream& source, uint64_t count, const CentroidGrid& grid,
                   std::vector<CellStats>& cells);
  Status distribute(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                    const GroupFn& group_of, uint32_t depth);
  Status restream_groups(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                         const GroupFn& group_of, uint32_t depth);
  Status spill_groups(const SourceStream& source, uint64_t count, const GroupPlan& plan,
                      const GroupFn& group_of, uint32_t depth);
  // Packs group g of `plan` (a part of `count` triangles) from `group_stream`.
  Status pack_group(const SourceStream& group_stream, uint64_t count, const GroupPlan& plan, uint32_t g,
                    uint32_t depth);
  Status build_group_in_memory(const PackedStream& stream, uint64_t count);

  PackContext& context_;
  BrickWriter& bricks_;
  uint32_t spill_serial_ = 0;  // spill files of different levels never share names
};

}  // namespace outcore::packing
