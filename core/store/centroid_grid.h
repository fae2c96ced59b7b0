// Out-of-core grouping for the packer: a coarse grid over triangle centroids
// whose per-cell counts and bounds come from one streaming pass, and a plan
// that cuts the grid along cell planes (binned SAH over the cells) into groups
// small enough to partition into bricks in memory. A second pass then streams
// each triangle into its group's spill file.
//
// Thread-safety: CentroidGrid is immutable after construction; plan_groups is a
// pure function.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry/aabb.h"

namespace outcore {

class CentroidGrid {
 public:
  // Cells are roughly cubic, at most max_cells in all; flat axes get one cell.
  CentroidGrid(const Aabb& centroid_bounds, uint32_t max_cells);

  uint32_t cell_of(const Vec3f& centroid) const {
    const std::array<uint32_t, 3> index = cell_coords(centroid);
    return (index[2] * resolution_[1] + index[1]) * resolution_[0] + index[0];
  }
  // The cell's (x, y, z) indices; cell_of() flattens them x fastest.
  std::array<uint32_t, 3> cell_coords(const Vec3f& centroid) const {
    std::array<uint32_t, 3> index;
    for (int axis = 0; axis < 3; ++axis) {
      const float t = (centroid[axis] - bounds_.lo[axis]) * scale_[axis];
      const int k = static_cast<int>(t);
      index[axis] = static_cast<uint32_t>(std::clamp(k, 0, static_cast<int>(resolution_[axis]) - 1));
    }
    return index;
  }
  uint32_t cell_count() const { return resolution_[0] * resolution_[1] * resolution_[2]; }
  const std::array<uint32_t, 3>& resolution() const { return resolution_; }

 private:
  Aabb bounds_;
  std::array<uint32_t, 3> resolution_{1, 1, 1};
  std::array<float, 3> scale_{0, 0, 0};
};

struct CellStats {
  uint64_t count = 0;
  Aabb bounds;           // of the triangles whose centroid falls in the cell
  Aabb centroid_bounds;  // of their centroids
};

struct GroupPlan {
  uint32_t group_count = 0;
  std::vector<uint32_t> cell_to_group;  // kNoGroup for empty cells
  std::vector<uint64_t> group_counts;
  std::vector<Aabb> group_centroid_bounds;
  static constexpr uint32_t kNoGroup = 0xffffffffu;
};

// Groups hold at most max_group_triangles unless a single cell holds more (the
// packer then recurses into that group with a finer grid). The SAH charges
// each side half a cost_unit per cost_unit-sized piece it will need (0 means
// max_group_triangles): groups come out full, while the brick size as the unit
// makes cuts fall where bricks would split anyway (between objects).
GroupPlan plan_groups(const CentroidGrid& grid, std::span<const CellStats> cells,
                      uint64_t max_group_triangles, uint64_t cost_unit = 0);

}  // namespace outcore
