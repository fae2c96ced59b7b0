// Filing triangles under a GridLattice's cells and sorting them into the
// compact arrays (Lagae & Dutré 2008: one start per cell, one triangle
// index per reference) — the uniform grid's build and both levels of the
// hierarchical grid's.
//
// file_triangles() files each triangle under every cell its bounds span
// that its plane may touch (TriangleBoxOverlap::plane_may_touch_box,
// triangle_box_overlap.h, on the closed cell grown by a tiny margin), the
// test made only for triangles whose bounds span cells along more than one
// axis, since a connected triangle spread along one row of cells touches
// all of them. Conservative: a triangle is never left out of a cell it
// touches. The plane alone, not the full separating-axis test: on the
// bunny the nine edge axes cost a quarter of the build and saved 2 % of
// the trace (callgrind; docs/BENCHMARKS.md, "Grids").
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/grid/grid_lattice.h"
#include "core/geometry/triangle.h"

namespace outcore {

struct CellPair {
  uint32_t cell;
  uint32_t triangle;
};

// Appends the (cell, triangle) pairs of triangles[which[k]] (of every
// triangle when `which` is empty), in that order, to `pairs`; false when
// `pairs` would exceed `cap` (the caller coarsens).
bool file_triangles(const GridLattice& lattice, std::span<const Triangle> triangles,
                    std::span<const uint32_t> which, uint64_t cap, std::vector<CellPair>& pairs);

// Appends cell_count starts to cell_starts (offsets into refs, continuing
// after refs' current end) and the pairs' triangles to refs, sorted by cell
// with each cell's triangles in the pairs' order (a counting sort). The
// caller appends the final start (refs.size()) after the last grid.
// Returns the scratch bytes it used.
uint64_t append_cells(std::span<const CellPair> pairs, uint64_t cell_count,
                      std::vector<uint32_t>& cell_starts, std::vector<uint32_t>& refs);

}  // namespace outcore
