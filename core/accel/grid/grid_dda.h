// The 3D-DDA (Amanatides & Woo 1987) over a GridLattice, shared by the
// uniform grid (uniform_grid_traversal.h) and both levels of the
// hierarchical grid (hgrid/hierarchical_grid_traversal.h): the ray's segment
// is clipped to the lattice's bounds, the cell holding its start is found,
// and the walk steps from cell to cell in the order the ray crosses their
// boundaries, handing each to the caller; it stops when the next cell
// begins beyond the best hit (a triangle spanning several cells must not
// end the walk early with a farther hit), at the end of the segment, or
// when the caller says so (occlusion).
//
// Conservative in float, as the kd-tree's walk: every boundary crossing
// (boundary - origin) / direction is widened by kBoxMargin (relative) into
// an interval [lo, hi], and the walk keeps, per axis, the run of cells the
// ray may be in given those intervals (usually one; two for the moment
// between lo and hi), visiting every cell of the runs' product once. So a
// ray through a cell corner or along an edge visits every cell it may touch
// in float, a hit just past a boundary never hides a nearer or equal one in
// the next cell, and the walk stops only when the next cell's widened entry
// lies beyond the best hit. A ray parallel to an axis stays in the cells
// holding its origin along it (a point on a boundary is in both cells'
// closed boxes, and the builders file triangles by closed boxes).
//
// Thread-safety: pure functions.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>

#include "core/accel/grid/grid_lattice.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace grid_detail {

inline constexpr float kInf = std::numeric_limits<float>::infinity();

// One axis of the walk. Cells along it are counted in the ray's travel
// order (k = 0 first); the ray may be in cells back .. front.
struct AxisRun {
  uint32_t back = 0, front = 0;
  uint32_t cells = 1;
  bool forward = true;
  float origin = 0, inverse_direction = 0;
  float next_entry = kInf;  // widened start of cell front + 1's part, or inf
  float front_exit = kInf;  // widened end of cell front's part, or inf (the last cell)
  float back_exit = kInf;   // widened end of cell back's part, or inf (the last cell)

  bool single() const { return back == front; }
  // Moves front to the next cell; its crossing out gives both the next
  // entry and its exit (one boundary computed a step).
  template <class CrossingAt>
  void step(CrossingAt&& crossing_after) {
    ++front;
    if (front + 1 < cells) {
      const auto c = crossing_after(front);
      next_entry = c.lo;
      front_exit = c.hi;
    } else {
      next_entry = front_exit = kInf;
    }
  }

  uint32_t cell(uint32_t k) const { return forward ? k : cells - 1 - k; }
};

// The widened t at which the ray crosses from travel cell k into k + 1.
struct Crossing {
  float lo, hi;
};
inline Crossing crossing(const GridLattice& grid, int axis, const AxisRun& run, uint32_t k) {
  const uint32_t cell = run.cell(k);
  const uint32_t boundary_index = run.forward ? cell + 1 : cell;
  const float t = (grid.boundary(axis, boundary_index) - run.origin) * run.inverse_direction;
  // NaN: a direction so small its inverse overflowed and the origin on the
  // boundary; the crossing time is unknown, so the ray may be on either side.
  if (t != t) return {-kInf, kInf};
  return {kd_detail::widen_down(t), kd_detail::widen_up(t)};
}

// The run of cells along `axis` the ray may be in at t = start.
inline AxisRun start_run(const GridLattice& grid, int axis, const Ray& ray, float inverse_direction,
                         float start) {
  AxisRun run;
  run.cells = grid.resolution[axis];
  run.forward = ray.direction[axis] >= 0.0f;
  run.origin = ray.origin[axis];
  run.inverse_direction = inverse_direction;
  const bool moving = ray.direction[axis] != 0.0f;
  const float at_start = moving ? ray.origin[axis] + start * ray.direction[axis] : ray.origin[axis];
  run.back = run.front = run.cell(grid.highest_cell_holding(axis, at_start));  // cell() is its own inverse
  if (!moving) return run;
  // The start cell may be off by rounding: widen the run to every cell the
  // ray may be in at `start`.
  while (run.back > 0 && crossing(grid, axis, run, run.back - 1).hi >= start) --run.back;
  while (run.front + 1 < run.cells && crossing(grid, axis, run, run.front).lo <= start) ++run.front;
  if (run.front + 1 < run.cells) {
    const Crossing c = crossing(grid, axis, run, run.front);
    run.next_entry = c.lo;
    run.front_exit = c.hi;
  }
  if (run.back + 1 < run.cells) run.back_exit = crossing(grid, axis, run, run.back).hi;
  return run;
}

// Calls visit_cell(c) (c = lattice.cell_index(x, y, z)) for the cells the
// segment [tmin, limit] may touch, front to back; visit_cell returns true to
// stop the walk. `limit` is the best hit so far (visit_cell lowers it).
template <class VisitCell>
inline void walk_cells(const GridLattice& grid, const Ray& ray, const bvh_detail::BoxRay& box_ray, float tmin,
                       float& limit, VisitCell&& visit_cell) {
  float segment_min, segment_max;
  if (!kd_detail::clip_to_bounds(grid.bounds, ray, box_ray, tmin, limit, segment_min, segment_max)) return;
  std::array<AxisRun, 3> runs;
  for (int a = 0; a < 3; ++a) runs[a] = start_run(grid, a, ray, box_ray.inverse_direction[a], segment_min);

  // Visits the cells in the product of the runs, axis `fixed` pinned to its
  // front cell (or every cell of every run when fixed < 0).
  auto visit = [&](int fixed) {
    // Usually one cell: every run single, or only the axis just stepped
    // still holding the cell it left (which the product skips).
    const bool others_single = (fixed == 0 || runs[0].single()) && (fixed == 1 || runs[1].single()) &&
                               (fixed == 2 || runs[2].single());
    if (others_single) {
      return visit_cell(grid.cell_index(runs[0].cell(runs[0].front), runs[1].cell(runs[1].front),
                                        runs[2].cell(runs[2].front)));
    }
    std::array<uint32_t, 3> from, to;
    for (int a = 0; a < 3; ++a) {
      from[a] = a == fixed ? runs[a].front : runs[a].back;
      to[a] = runs[a].front;
    }
    for (uint32_t kz = from[2]; kz <= to[2]; ++kz) {
      for (uint32_t ky = from[1]; ky <= to[1]; ++ky) {
        for (uint32_t kx = from[0]; kx <= to[0]; ++kx) {
          if (visit_cell(grid.cell_index(runs[0].cell(kx), runs[1].cell(ky), runs[2].cell(kz)))) return true;
        }
      }
    }
    return false;
  };

  if (visit(-1)) return;
  while (true) {
    int axis = 0;
    if (runs[1].next_entry < runs[axis].next_entry) axis = 1;
    if (runs[2].next_entry < runs[axis].next_entry) axis = 2;
    const float entry = runs[axis].next_entry;
    // Also ends the walk when no axis has a cell left (entry is inf).
    if (!(entry <= limit && entry <= segment_max)) return;
    // Cells the ray has surely left by `entry` drop out of the runs.
    for (AxisRun& run : runs) {
      while (run.back < run.front && run.back_exit < entry) {
        ++run.back;
        run.back_exit = run.back == run.front
                            ? run.front_exit
                            : crossing(grid, static_cast<int>(&run - runs.data()), run, run.back).hi;
      }
    }
    AxisRun& run = runs[axis];
    run.step([&](uint32_t k) { return crossing(grid, axis, run, k); });
    if (visit(axis)) return;
  }
}

}  // namespace grid_detail
}  // namespace outcore
