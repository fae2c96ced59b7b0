// UniformGrid: a brick's triangles in a uniform grid stored compactly (Lagae
// & Dutré 2008, "Compact, fast and robust grids for ray tracing"): the
// triangles' bounds cut into resolution[0] x resolution[1] x resolution[2]
// cells of equal size, one start offset per cell (cell c's references are
// refs[cell_starts[c] .. cell_starts[c + 1])) and one triangle index per
// reference (a triangle touching several cells is referenced by each), and
// per triangle what a hit reports besides t, u, v. Cells are numbered x
// fastest: c = x + resolution[0] * (y + resolution[1] * z).
//
// The cells' geometry is a GridLattice (grid_lattice.h: one float
// expression for the boundaries, which the builder and the traversal
// share; the outermost cells reach the grid's bounds, those of every
// triangle). A triangle is filed under every cell whose closed box it may touch
// (triangle_box_overlap.h), so a point on a boundary is in the cells on both
// sides.
//
// Built by UniformGridBuilder (uniform_grid_builder.h), traversed by
// uniform_grid_traversal.h; UniformGrid owns its arrays, UniformGridView is
// what traversal reads. validate() checks a view from elsewhere (a subtree
// file) so that it is an error, never a crash.
//
// Thread-safety: plain values; immutable grids and views may be read from
// many threads.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/grid/grid_lattice.h"
#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// The most cells along one axis, and in all (cell indices and starts fit 32
// bits with room to spare).
inline constexpr uint32_t kMaxGridResolution = 4096;
inline constexpr uint64_t kMaxGridCells = uint64_t{1} << 28;

struct UniformGridView : GridLattice {
  std::span<const uint32_t> cell_starts;  // cell_count() + 1 offsets into refs; empty without triangles
  std::span<const uint32_t> refs;
  std::span<const Triangle> triangles;
  std::span<const BvhHitRecord> records;  // records[k] belongs to triangles[k]

  Status validate() const;
};

struct UniformGrid : GridLattice {
  std::vector<uint32_t> cell_starts;
  std::vector<uint32_t> refs;
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;

  UniformGridView view() const { return {{*this}, cell_starts, refs, triangles, records}; }
  uint64_t memory_bytes() const {
    return cell_starts.capacity() * sizeof(uint32_t) + refs.capacity() * sizeof(uint32_t) +
           triangles.capacity() * sizeof(Triangle) + records.capacity() * sizeof(BvhHitRecord);
  }
};

}  // namespace outcore
