#include "core/store/centroid_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace outcore {

CentroidGrid::CentroidGrid(const Aabb& centroid_bounds, uint32_t max_cells) : bounds_(centroid_bounds) {
  const Vec3f extent = centroid_bounds.extent();
  double volume = 1.0;
  int live_axes = 0;
  for (int axis = 0; axis < 3; ++axis) {
    if (extent[axis] > 0.0f) {
      volume *= extent[axis];
      ++live_axes;
    }
  }
  if (live_axes == 0) return;
  const double cell = std::pow(volume / std::max<uint32_t>(1, max_cells), 1.0 / live_axes);
  for (int axis = 0; axis < 3; ++axis) {
    if (extent[axis] <= 0.0f) continue;
    const double cells = std::clamp(std::floor(extent[axis] / cell), 1.0, 4096.0);
    resolution_[axis] = static_cast<uint32_t>(cells);
    scale_[axis] = static_cast<float>(cells / extent[axis]);
    if (!std::isfinite(scale_[axis])) {
      resolution_[axis] = 1;
      scale_[axis] = 0.0f;
    }
  }
  // Rounding can overshoot the cell budget a little; shrink the largest axis.
  while (static_cast<uint64_t>(resolution_[0]) * resolution_[1] * resolution_[2] >
         std::max<uint32_t>(1, max_cells)) {
    const int axis =
        static_cast<int>(std::max_element(resolution_.begin(), resolution_.end()) - resolution_.begin());
    resolution_[axis] = std::max<uint32_t>(1, resolution_[axis] / 2);
    scale_[axis] = static_cast<float>(resolution_[axis] / static_cast<double>(extent[axis]));
  }
}

namespace {

struct CellBox {
  std::array<uint32_t, 3> lo, hi;  // half-open
};

class GroupPlanner {
 public:
  GroupPlanner(const CentroidGrid& grid, std::span<const CellStats> cells, uint64_t max_group,
               uint64_t cost_unit)
      : res_(grid.resolution()),
        cells_(cells),
        max_group_(max_group),
        unit_(std::max<uint64_t>(1, cost_unit)) {
    plan_.cell_to_group.assign(cells.size(), GroupPlan::kNoGroup);
  }

  GroupPlan run() {
    split({{0, 0, 0}, res_});
    return std::move(plan_);
  }

 private:
  // Triangles plus half a unit's worth per unit the side will need: with
  // whole groups as the unit, fuller groups mean fewer passes over the input.
  double side_cost(uint64_t count) const {
    const uint64_t units = (count + unit_ - 1) / unit_;
    return static_cast<double>(count) + 0.5 * static_cast<double>(unit_) * static_cast<double>(units);
  }

  uint32_t index(uint32_t x, uint32_t y, uint32_t z) const { return (z * res_[1] + y) * res_[0] + x; }

  template <class Fn>
  void for_each_cell(const CellBox& box, Fn&& fn) const {
    for (uint32_t z = box.lo[2]; z < box.hi[2]; ++z)
      for (uint32_t y = box.lo[1]; y < box.hi[1]; ++y)
        for (uint32_t x = box.lo[0]; x < box.hi[0]; ++x) fn(index(x, y, z), std::array<uint32_t, 3>{x, y, z});
  }

  void split(const CellBox& box) {
    uint64_t total = 0;
    for_each_cell(box, [&](uint32_t i, auto) { total += cells_[i].count; });
    if (total == 0) return;
    double best_cost = std::numeric_limits<double>::infinity();
    int best_axis = -1;
    uint32_t best_plane = 0;
    if (total > max_group_) {
      for (int axis = 0; axis < 3; ++axis) {
        const uint32_t slabs = box.hi[axis] - box.lo[axis];
        if (slabs < 2) continue;
        std::vector<CellStats> slab(slabs);
        for_each_cell(box, [&](uint32_t i, const std::array<uint32_t, 3>& xyz) {
          CellStats& s = slab[xyz[axis] - box.lo[axis]];
          s.count += cells_[i].count;
          s.bounds.extend(cells_[i].bounds);
        });
        std::vector<double> right_cost(slabs + 1, -1.0);
        CellStats right;
        for (uint32_t k = slabs; k-- > 1;) {
          right.count += slab[k].count;
          right.bounds.extend(slab[k].bounds);
          right_cost[k] = right.count ? right.bounds.half_area() * side_cost(right.count) : -1.0;
        }
        CellStats left;
        for (uint32_t k = 0; k + 1 < slabs; ++k) {
          left.count += slab[k].count;
          left.bounds.extend(slab[k].bounds);
          if (left.count == 0 || right_cost[k + 1] < 0.0) continue;
          const double cost = left.bounds.half_area() * side_cost(left.count) + right_cost[k + 1];
          if (cost < best_cost) {
            best_cost = cost;
            best_axis = axis;
            best_plane = box.lo[axis] + k + 1;
          }
        }
      }
    }
    if (best_axis < 0) {
      const uint32_t group = plan_.group_count++;
      plan_.group_counts.push_back(0);
      plan_.group_centroid_bounds.emplace_back();
      for_each_cell(box, [&](uint32_t i, auto) {
        if (cells_[i].count == 0) return;
        plan_.cell_to_group[i] = group;
        plan_.group_counts[group] += cells_[i].count;
        plan_.group_centroid_bounds[group].extend(cells_[i].centroid_bounds);
      });
      return;
    }
    CellBox left = box, right = box;
    left.hi[best_axis] = best_plane;
    right.lo[best_axis] = best_plane;
    split(left);
    split(right);
  }

  std::array<uint32_t, 3> res_;
  std::span<const CellStats> cells_;
  uint64_t max_group_;
  uint64_t unit_;
  GroupPlan plan_;
};

}  // namespace

GroupPlan plan_groups(const CentroidGrid& grid, std::span<const CellStats> cells,
                      uint64_t max_group_triangles, uint64_t cost_unit) {
  return GroupPlanner(grid, cells, max_group_triangles, cost_unit > 0 ? cost_unit : max_group_triangles)
      .run();
}

}  // namespace outcore
