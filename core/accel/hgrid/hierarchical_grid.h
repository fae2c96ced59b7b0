// HierarchicalGrid: a brick's triangles in nested uniform grids, the seed's
// answer to the "teapot in a stadium". A coarse root grid over the
// triangles' bounds (about one cell per 16 triangles), and in every cell
// holding more than max_cell_triangles triangles a grid of its own at the
// uniform grid's density for that cell's triangle count, recursively up to
// max_levels levels: the two-level grid of Kalojanov, Billeter & Slusallek
// 2011 ("Two-level grids for ray tracing on GPUs") when two levels are
// enough, nested further (as Jevans & Wyvill's adaptive grids) where a
// small dense object shares a cell with large sparse geometry.
//
// Each nested grid covers its cell clipped to the bounds of the triangles
// filed under it, not the whole cell, so its cells hug what is there: the
// teapot on the stadium's floor gets a grid over the floor's slab, whose
// cells around the teapot nest again over the teapot alone. A ray crosses
// the rest of the cell without a test.
//
// Layout: grids[0] is the root; a HgridGrid holds its box and resolution
// and the index of its first cell; the cells of all grids one grid after
// the other, in grid order; a cell is either a run of triangle references
// (first, count) or a nested grid (its index, always after its parent's);
// one triangle index per reference; per triangle what a hit reports
// besides t, u, v. Every grid's cell geometry follows from
// GridLattice::over(box, resolution) (grid/grid_lattice.h), the one float
// expression builder and walk share.
//
// Built by HierarchicalGridBuilder (hierarchical_grid_builder.h), traversed
// by hierarchical_grid_traversal.h. validate() checks a view from elsewhere
// (a subtree file) so that it is an error, never a crash.
//
// Thread-safety: plain values; immutable grids and views may be read from
// many threads.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/grid/grid_lattice.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// The most cells along one axis of any grid, in all, and the deepest
// nesting (levels, the root's included) the traversal supports.
inline constexpr uint32_t kMaxHgridResolution = 1024;
inline constexpr uint64_t kMaxHgridCells = uint64_t{1} << 28;
inline constexpr uint32_t kMaxHgridLevels = 4;

struct HgridGrid {
  Aabb box;                 // its cells' bounds: its parent cell clipped to its triangles' bounds
  uint32_t first_cell = 0;  // its first cell in cells
  std::array<uint16_t, 3> resolution{1, 1, 1};
  uint16_t unused = 0;

  uint64_t cell_count() const { return uint64_t{resolution[0]} * resolution[1] * resolution[2]; }
  GridLattice lattice() const {
    return GridLattice::over(box, {resolution[0], resolution[1], resolution[2]});
  }
};
static_assert(sizeof(HgridGrid) == 36);

struct HgridCell {
  uint32_t first = 0;  // the first reference, or the nested grid
  uint32_t bits = 0;   // bit 0: a nested grid; above it the reference count

  static HgridCell references(uint32_t first, uint32_t count) { return {first, count << 1}; }
  static HgridCell nested(uint32_t grid) { return {grid, 1}; }
  bool is_nested() const { return (bits & 1u) != 0; }
  uint32_t grid() const { return first; }
  uint32_t count() const { return bits >> 1; }
};
static_assert(sizeof(HgridCell) == 8);

struct HierarchicalGridView {
  std::span<const HgridGrid> grids;  // grids[0] is the root; empty without triangles
  std::span<const HgridCell> cells;
  std::span<const uint32_t> refs;
  std::span<const Triangle> triangles;
  std::span<const BvhHitRecord> records;  // records[k] belongs to triangles[k]

  Status validate() const;
};

struct HierarchicalGrid {
  std::vector<HgridGrid> grids;
  std::vector<HgridCell> cells;
  std::vector<uint32_t> refs;
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;

  HierarchicalGridView view() const { return {grids, cells, refs, triangles, records}; }
  uint64_t memory_bytes() const {
    return grids.capacity() * sizeof(HgridGrid) + cells.capacity() * sizeof(HgridCell) +
           refs.capacity() * sizeof(uint32_t) + triangles.capacity() * sizeof(Triangle) +
           records.capacity() * sizeof(BvhHitRecord);
  }
};

}  // namespace outcore
