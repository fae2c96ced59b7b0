// GridLattice: the geometry of a uniform grid of cells over a box — its
// bounds, resolution[0] x resolution[1] x resolution[2] cells of equal size,
// numbered x fastest (c = x + resolution[0] * (y + resolution[1] * z)) —
// shared by the uniform grid (uniform_grid.h) and both levels of the
// hierarchical grid (hgrid/hierarchical_grid.h), whose builders file
// triangles by it and whose walks (grid_dda.h) step through it.
//
// Cell boundaries are defined by one float expression, boundary(axis, j) =
// bounds.lo + j * cell_width (j = 1 .. resolution - 1), and the outermost
// cells reach the bounds; cell_width is (bounds.hi - bounds.lo) /
// resolution in float, computed by over(). Builders and walks use these
// alone, so both see the same cells bit for bit.
//
// Thread-safety: a plain value.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "core/geometry/aabb.h"
#include "core/util/status.h"

namespace outcore {

// Cells of a resolution: resolution[0] * resolution[1] * resolution[2].
inline uint64_t cell_count_of(const std::array<uint32_t, 3>& resolution) {
  return uint64_t{resolution[0]} * resolution[1] * resolution[2];
}

struct GridLattice {
  Aabb bounds;
  std::array<uint32_t, 3> resolution{0, 0, 0};
  Vec3f cell_width;

  // The lattice of `resolution` cells over `box`.
  static GridLattice over(const Aabb& box, const std::array<uint32_t, 3>& resolution) {
    GridLattice lattice{box, resolution, {}};
    for (int a = 0; a < 3; ++a) {
      lattice.cell_width[a] = (box.hi[a] - box.lo[a]) / static_cast<float>(resolution[a]);
    }
    return lattice;
  }

  uint64_t cell_count() const { return cell_count_of(resolution); }
  uint32_t cell_index(uint32_t x, uint32_t y, uint32_t z) const {
    return x + resolution[0] * (y + resolution[1] * z);
  }
  // The plane between cells j - 1 and j along axis (1 <= j < resolution).
  float boundary(int axis, uint32_t j) const {
    return bounds.lo[axis] + static_cast<float>(j) * cell_width[axis];
  }
  // Where cell j begins and ends along axis.
  float cell_lo(int axis, uint32_t j) const { return j == 0 ? bounds.lo[axis] : boundary(axis, j); }
  float cell_hi(int axis, uint32_t j) const {
    return j + 1 == resolution[axis] ? bounds.hi[axis] : boundary(axis, j + 1);
  }
  Aabb cell_box(uint32_t x, uint32_t y, uint32_t z) const {
    return {{cell_lo(0, x), cell_lo(1, y), cell_lo(2, z)}, {cell_hi(0, x), cell_hi(1, y), cell_hi(2, z)}};
  }
  // The lowest and highest cell along axis whose closed extent holds x
  // (x inside the bounds; outside, the nearest end cell).
  uint32_t lowest_cell_holding(int axis, float x) const;
  uint32_t highest_cell_holding(int axis, float x) const;
  // The same from a first guess `cell` (any cell; a near one takes fewer
  // exact comparisons): for callers that guess faster (grid_filing.cpp).
  uint32_t lowest_cell_holding_from(int axis, float x, uint32_t cell) const {
    // Cell j holds x when boundary(j) <= x <= boundary(j + 1).
    while (cell > 0 && boundary(axis, cell) >= x) --cell;
    while (cell + 1 < resolution[axis] && boundary(axis, cell + 1) < x) ++cell;
    return cell;
  }
  uint32_t highest_cell_holding_from(int axis, float x, uint32_t cell) const {
    while (cell + 1 < resolution[axis] && boundary(axis, cell + 1) <= x) ++cell;
    while (cell > 0 && boundary(axis, cell) > x) --cell;
    return cell;
  }

  // Resolution within [1, max_resolution] per axis and cell_count() within
  // max_cells; bounds and widths finite and ordered. `what` prefixes errors.
  Status validate(const std::string& what, uint32_t max_resolution, uint64_t max_cells) const;
};

}  // namespace outcore
