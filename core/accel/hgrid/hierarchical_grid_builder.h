// HierarchicalGridBuilder: a HierarchicalGrid over a brick's triangles in
// linear time per level, breadth first: a grid's resolution from the
// density rule (the uniform grid's, UniformGridBuilder::resolution_for) over
// its box — the root's at top_cells_per_triangle, every nested grid's at
// cells_per_triangle for its own triangle count — its triangles filed under
// the cells they may touch (grid/grid_filing.h, conservative), then each
// cell holding more than max_cell_triangles triangles, below max_levels,
// queued as a nested grid over the cell clipped to its triangles' bounds,
// and every other cell made a run of references.
//
// Budgets, so that reserve_bytes bounds memory for the cache's reservation:
// at most N / 4 + 64 grids, kMaxCellsPerTriangle * N + 4096 cells and
// kMaxReferencesPerTriangle * N + 64 references in all. A grid whose
// cells or references would pass what is left is coarsened by halving; a
// cell whose nested grid cannot fit (or would be one cell) stays a run of
// references.
//
// Thread-safety: build() is reentrant (no shared state).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/accel/hgrid/hierarchical_grid.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

class HierarchicalGridBuilder {
 public:
  struct Config {
    float top_cells_per_triangle = 1.0f / 16.0f;  // the root grid's density, in (0, 1]
    float cells_per_triangle = 2.0f;              // each nested grid's density, in (0, 8]
    uint32_t max_cell_triangles = 8;              // a cell holding more gets a grid of its own
    uint32_t max_levels = 3;                      // the root's included, 1 .. kMaxHgridLevels

    Status validate() const;
    // Sets the option `key` (top_cells_per_triangle, cells_per_triangle,
    // max_cell_triangles, max_levels) from `value`: false when `key` is
    // none of them, an error naming `structure` when the value is
    // malformed.
    Expected<bool> parse_option(std::string_view structure, const std::string& key, const std::string& value);
  };

  static constexpr uint64_t kMaxReferencesPerTriangle = 8;
  static constexpr uint64_t kMaxCellsPerTriangle = 8;
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 24;

  struct Result {
    HierarchicalGrid tree;
    uint64_t peak_bytes = 0;  // the build's own scratch at its largest (pairs, queued cells' lists)
  };

  // triangles: usable ones (finite, not degenerate); ids[k] belongs to
  // triangles[k]. The grid keeps them in this order.
  static Result build(std::vector<Triangle> triangles, const std::vector<TriangleId>& ids,
                      const Config& config);

  // The budgets build() keeps (the serialiser checks payloads against them).
  static uint64_t grids_cap(uint64_t n) { return n / 4 + 64; }
  static uint64_t cells_cap(uint64_t n) { return kMaxCellsPerTriangle * n + 4096; }
  static uint64_t references_cap(uint64_t n) { return kMaxReferencesPerTriangle * n + 64; }
  // Upper bounds, for n triangles: the grid's arrays, and the build's peak
  // scratch.
  static uint64_t tree_bytes_bound(uint64_t n);
  static uint64_t peak_bytes_bound(uint64_t n);
};

}  // namespace outcore
