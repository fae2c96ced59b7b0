// GeneratedPartition: the fast path for generated scenes. Groups are never
// spilled: each is filtered out of chunks regenerated on all cores
// (GeneratedChunks), so a scene of billions of triangles packs within the
// memory bound without touching the disk for anything but bricks. Each group
// in memory is cut along grid planes into subgroups of about kSubgroupBricks
// bricks, partitioned on all cores while earlier subgroups are checksummed
// and written, always in the same order: the bricks do not depend on the
// thread count. A cell holding more than fits (triangles sharing a centroid)
// goes to the general path (SpillPartition) over the inputs' stream.
//
// Thread-safety: one thread calls pack(); it uses TBB internally.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <span>
#include <vector>

#include "core/store/brick_writer.h"
#include "core/store/centroid_grid.h"
#include "core/store/generated_chunks.h"
#include "core/store/pack_context.h"
#include "core/store/spill_partition.h"

namespace outcore::packing {

// Triangles of a group in memory, reused across groups (one allocation, pages
// faulted once); not value-initialised, every slot is written before it is read.
struct TriangleBuffer {
  struct Free {
    void operator()(PackedTriangle* p) const { std::free(p); }
  };
  std::unique_ptr<PackedTriangle, Free> data;
  uint64_t capacity = 0;
  Status reserve(uint64_t count);
};

class GeneratedPartition {
 public:
  // `inputs` streams every input tagged with ids, for the general path.
  GeneratedPartition(PackContext& context, const GeneratedChunks& chunks, BrickWriter& bricks,
                     SpillPartition& general, PackedStream inputs)
      : context_(context), chunks_(chunks), bricks_(bricks), general_(general), inputs_(std::move(inputs)) {}

  // Packs the scene `scan` describes into bricks.
  Status pack(const ScanResult& scan);

 private:
  // How one level of groups is cut into subgroups, and which chunks feed
  // each group.
  struct GroupLayout {
    GroupPlan plan;
    std::vector<uint32_t> cell_to_sub;                // per cell: its subgroup in its group
    std::vector<std::vector<uint64_t>> sub_counts;    // per group that fits: triangles per subgroup
    std::vector<std::vector<uint32_t>> group_chunks;  // per group: chunks that can touch it
    uint64_t largest = 0;                             // triangles of the largest group that fits
  };

  Status pack_one_group(uint64_t count);
  Status histogram(const CentroidGrid& grid, uint64_t count, std::vector<CellStats>& cells) const;
  void plan_subgroups(const CentroidGrid& grid, const std::vector<CellStats>& cells, uint64_t sub_max,
                      GroupLayout& layout) const;
  void find_group_chunks(const CentroidGrid& grid, GroupLayout& layout) const;
  Status pack_oversized_group(const CentroidGrid& grid, const GroupPlan& plan, uint32_t g);
  template <class Classify>
  Status fill_group(std::span<const uint32_t> chunk_ids, const Classify& classify,
                    std::span<const uint64_t> sub_counts, PackedTriangle* out);
  Status write_subgroups(PackedTriangle* data, std::span<const uint64_t> sub_counts);

  PackContext& context_;
  const GeneratedChunks& chunks_;
  BrickWriter& bricks_;
  SpillPartition& general_;
  PackedStream inputs_;
  TriangleBuffer group_buffer_;
};

}  // namespace outcore::packing
