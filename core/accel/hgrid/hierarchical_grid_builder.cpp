#include "core/accel/hgrid/hierarchical_grid_builder.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <deque>
#include <span>
#include <utility>

#include "core/accel/grid/grid_filing.h"
#include "core/accel/grid/uniform_grid_builder.h"
#include "core/accel/triangle_hit_records.h"
#include "core/util/parse_number.h"

namespace outcore {
namespace {

// A grid waiting to be made: its slot, box, level (the root's is 0) and
// triangles.
struct PendingGrid {
  uint32_t slot;
  Aabb box;
  uint32_t level;
  std::vector<uint32_t> triangles;
};

class HgridBuild {
 public:
  HgridBuild(HierarchicalGrid& grid, const HierarchicalGridBuilder::Config& config)
      : grid_(grid), config_(config), n_(grid.triangles.size()) {}

  // Returns the peak scratch bytes.
  uint64_t run() {
    PendingGrid root{0, {}, 0, {}};
    for (const Triangle& tri : grid_.triangles) root.box.extend(tri.bounds());
    root.triangles.resize(n_);
    for (uint32_t k = 0; k < n_; ++k) root.triangles[k] = k;
    grid_.grids.emplace_back();
    outstanding_ = n_;
    std::deque<PendingGrid> queue;
    queue.push_back(std::move(root));
    uint64_t queued_bytes = n_ * sizeof(uint32_t);
    // Breadth first, so grids are made in the order their slots were
    // given and their cells follow one another in grid order.
    while (!queue.empty()) {
      PendingGrid pending = std::move(queue.front());
      queue.pop_front();
      queued_bytes -= pending.triangles.capacity() * sizeof(uint32_t);
      peak_ = std::max(peak_, make(pending, queue, queued_bytes));
    }
    return peak_;
  }

 private:
  UniformGridBuilder::Config density(uint32_t level) const {
    UniformGridBuilder::Config config;
    config.cells_per_triangle = level == 0 ? config_.top_cells_per_triangle : config_.cells_per_triangle;
    config.max_resolution = kMaxHgridResolution;
    return config;
  }

  // Files the pending grid's triangles at the density rule's resolution,
  // coarsened until its cells and references fit what is left (one cell
  // and its triangles always fit: each queued grid has a cell set aside, and
  // its triangles are counted in outstanding_).
  void file(const PendingGrid& pending, uint64_t queued, std::array<uint32_t, 3>& resolution) {
    const uint64_t count = pending.triangles.size();
    const uint64_t cells_left = HierarchicalGridBuilder::cells_cap(n_) - grid_.cells.size() - queued;
    // This grid's references replace the `count` its cell holds now.
    const uint64_t refs_left = HierarchicalGridBuilder::references_cap(n_) - (outstanding_ - count);
    resolution = UniformGridBuilder::resolution_for(pending.box, count, density(pending.level));
    while (true) {
      if (cell_count_of(resolution) <= cells_left) {
        pairs_.clear();
        if (file_triangles(GridLattice::over(pending.box, resolution), grid_.triangles, pending.triangles,
                           refs_left, pairs_)) {
          return;
        }
      }
      assert(cell_count_of(resolution) > 1);
      UniformGridBuilder::coarsen(resolution);
    }
  }

  // Makes the grid and queues its dense cells' grids; returns the scratch
  // in use at its largest.
  uint64_t make(PendingGrid& pending, std::deque<PendingGrid>& queue, uint64_t& queued_bytes) {
    std::array<uint32_t, 3> resolution;
    file(pending, queue.size(), resolution);
    outstanding_ += pairs_.size() - pending.triangles.size();
    const uint64_t first_cell = grid_.cells.size();
    HgridGrid& made = grid_.grids[pending.slot];  // before grids grow below
    made.box = pending.box;
    made.first_cell = static_cast<uint32_t>(first_cell);
    for (int a = 0; a < 3; ++a) made.resolution[a] = static_cast<uint16_t>(resolution[a]);
    const GridLattice lattice = made.lattice();
    // Each cell's triangles, by a counting sort of the pairs.
    const uint64_t cell_count = cell_count_of(resolution);
    starts_.clear();
    sorted_.clear();
    uint64_t scratch = append_cells(pairs_, cell_count, starts_, sorted_);
    starts_.push_back(static_cast<uint32_t>(sorted_.size()));
    scratch +=
        pairs_.capacity() * sizeof(CellPair) + (starts_.capacity() + sorted_.capacity()) * sizeof(uint32_t);
    grid_.cells.resize(grid_.cells.size() + cell_count);
    const bool may_nest = pending.level + 1 < config_.max_levels;
    for (uint32_t z = 0, c = 0; z < resolution[2]; ++z) {
      for (uint32_t y = 0; y < resolution[1]; ++y) {
        for (uint32_t x = 0; x < resolution[0]; ++x, ++c) {
          const std::span<const uint32_t> triangles(sorted_.data() + starts_[c], starts_[c + 1] - starts_[c]);
          const uint64_t cell = first_cell + c;
          // A nested grid needs a slot and, set aside, one cell.
          if (may_nest && triangles.size() > config_.max_cell_triangles &&
              grid_.grids.size() < HierarchicalGridBuilder::grids_cap(n_) &&
              grid_.cells.size() + queue.size() + 1 <= HierarchicalGridBuilder::cells_cap(n_)) {
            const uint32_t slot = static_cast<uint32_t>(grid_.grids.size());
            grid_.grids.emplace_back();
            grid_.cells[cell] = HgridCell::nested(slot);
            queue.push_back({slot, clipped_bounds(triangles, lattice.cell_box(x, y, z)), pending.level + 1,
                             std::vector<uint32_t>(triangles.begin(), triangles.end())});
            queued_bytes += triangles.size() * sizeof(uint32_t);
          } else {
            grid_.cells[cell] = append_references(triangles);
          }
        }
      }
    }
    return scratch + queued_bytes;
  }

  HgridCell append_references(std::span<const uint32_t> triangles) {
    const HgridCell cell = HgridCell::references(static_cast<uint32_t>(grid_.refs.size()),
                                                 static_cast<uint32_t>(triangles.size()));
    grid_.refs.insert(grid_.refs.end(), triangles.begin(), triangles.end());
    return cell;
  }

  // The triangles' bounds clipped to `cell`.
  Aabb clipped_bounds(std::span<const uint32_t> triangles, const Aabb& cell) const {
    Aabb box;
    for (const uint32_t k : triangles) box.extend(grid_.triangles[k].bounds());
    for (int a = 0; a < 3; ++a) {
      box.lo[a] = std::max(box.lo[a], cell.lo[a]);
      box.hi[a] = std::min(box.hi[a], cell.hi[a]);
    }
    return box;
  }

  HierarchicalGrid& grid_;
  const HierarchicalGridBuilder::Config& config_;
  const uint64_t n_;
  uint64_t outstanding_ = 0;  // references in cells made and grids queued
  uint64_t peak_ = 0;
  std::vector<CellPair> pairs_;
  std::vector<uint32_t> starts_, sorted_;
};

}  // namespace

Status HierarchicalGridBuilder::Config::validate() const {
  if (!(top_cells_per_triangle > 0.0f && top_cells_per_triangle <= 1.0f)) {
    return invalid_argument("hgrid: top_cells_per_triangle must be in (0, 1], got " +
                            std::to_string(top_cells_per_triangle));
  }
  if (!(cells_per_triangle > 0.0f && cells_per_triangle <= static_cast<float>(kMaxCellsPerTriangle))) {
    return invalid_argument("hgrid: cells_per_triangle must be in (0, " +
                            std::to_string(kMaxCellsPerTriangle) + "], got " +
                            std::to_string(cells_per_triangle));
  }
  if (max_cell_triangles < 1) return invalid_argument("hgrid: max_cell_triangles must be at least 1");
  if (max_levels < 1 || max_levels > kMaxHgridLevels) {
    return invalid_argument("hgrid: max_levels must be in [1, " + std::to_string(kMaxHgridLevels) +
                            "], got " + std::to_string(max_levels));
  }
  return Status::Ok();
}

Expected<bool> HierarchicalGridBuilder::Config::parse_option(std::string_view structure,
                                                             const std::string& key,
                                                             const std::string& value) {
  const std::string what = "brick accel " + std::string(structure) + ": option " + key;
  if (key == "top_cells_per_triangle" || key == "cells_per_triangle") {
    float& target = key == "cells_per_triangle" ? cells_per_triangle : top_cells_per_triangle;
    if (!parse_number(value, target) || !std::isfinite(target)) {
      return invalid_argument(what + " must be a number, got '" + value + "'");
    }
    return true;
  }
  if (key == "max_cell_triangles" || key == "max_levels") {
    if (!parse_number(value, key == "max_levels" ? max_levels : max_cell_triangles)) {
      return invalid_argument(what + " must be a whole number, got '" + value + "'");
    }
    return true;
  }
  return false;
}

uint64_t HierarchicalGridBuilder::tree_bytes_bound(uint64_t n) {
  return grids_cap(n) * sizeof(HgridGrid) + cells_cap(n) * sizeof(HgridCell) +
         references_cap(n) * sizeof(uint32_t) + n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// A grid's pairs (within the reference budget; capacity up to twice), its
// cells' starts and sorted lists (the counting sort's next slots too), and
// the queued grids' lists (within the reference budget).
uint64_t HierarchicalGridBuilder::peak_bytes_bound(uint64_t n) {
  return 2 * references_cap(n) * sizeof(CellPair) + 4 * (cells_cap(n) + 1) * sizeof(uint32_t) +
         3 * references_cap(n) * sizeof(uint32_t);
}

HierarchicalGridBuilder::Result HierarchicalGridBuilder::build(std::vector<Triangle> triangles,
                                                               const std::vector<TriangleId>& ids,
                                                               const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  HierarchicalGrid& grid = result.tree;
  if (triangles.empty()) return result;
  grid.records = hit_records_for(triangles, ids);
  grid.triangles = std::move(triangles);
  HgridBuild build(grid, config);
  result.peak_bytes = build.run();
  // Exact capacities: memory_bytes() then equals a reloaded grid's.
  grid.grids.shrink_to_fit();
  grid.cells.shrink_to_fit();
  grid.refs.shrink_to_fit();
  grid.triangles.shrink_to_fit();
  return result;
}

}  // namespace outcore
