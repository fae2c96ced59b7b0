// Traversal of a HierarchicalGridView for one ray: the conservative 3D-DDA
// (grid/grid_dda.h) through the root grid and, in each cell that nests a
// grid, through that grid (clipped to its box, the part of the cell its
// triangles occupy), recursively; the other cells' triangles are tested
// with a per-ray mailbox (triangle_mailbox.h). Each grid's walk stops as
// the uniform grid's does: when its next cell begins beyond the best hit (a
// triangle spanning cells must not end the walk early with a farther hit),
// at the end of its segment, or at any hit for occlusion. A nested grid's
// lattice is made from its box and resolution by GridLattice::over(), as
// the builder's was. Recursion is bounded by kMaxHgridLevels (validate()).
//
// Thread-safety: pure functions over an immutable grid.
#pragma once

#include <cstdint>

#include "core/accel/grid/grid_dda.h"
#include "core/accel/hgrid/hierarchical_grid.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace hgrid_detail {

// Walks grid g; true when leaf stopped the walk.
template <class Leaf>
inline bool walk_grid(const HierarchicalGridView& grid, uint32_t g, const Ray& ray,
                      const bvh_detail::BoxRay& box_ray, float tmin, float& limit, Leaf& leaf) {
  const HgridGrid& walked = grid.grids[g];
  const HgridCell* cells = grid.cells.data() + walked.first_cell;
  bool stopped = false;
  grid_detail::walk_cells(walked.lattice(), ray, box_ray, tmin, limit, [&](uint32_t c) {
    const HgridCell cell = cells[c];
    if (cell.is_nested()) {
      stopped = walk_grid(grid, cell.grid(), ray, box_ray, tmin, limit, leaf);
    } else {
      stopped = cell.count() != 0 && leaf(cell.first, cell.count(), limit);
    }
    return stopped;
  });
  return stopped;
}

// Calls leaf(first, count, limit) for the cells the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf>
inline void traverse(const HierarchicalGridView& grid, const Ray& ray, float tmin, float& limit,
                     Leaf&& leaf) {
  if (grid.grids.empty()) return;
  walk_grid(grid, 0, ray, bvh_detail::BoxRay(ray), tmin, limit, leaf);
}

}  // namespace hgrid_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test, class Mailbox = TriangleMailbox>
bool hgrid_closest_hit(const HierarchicalGridView& grid, const Ray& ray, Hit& best, Mailbox&& mailbox = {}) {
  return kd_detail::closest_hit<Test>(
      grid, ray, best,
      [&](float tmin, float& limit, auto&& leaf) { hgrid_detail::traverse(grid, ray, tmin, limit, leaf); },
      mailbox);
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test, class Mailbox = TriangleMailbox>
bool hgrid_any_hit(const HierarchicalGridView& grid, const Ray& ray, Mailbox&& mailbox = {}) {
  return kd_detail::any_hit<Test>(
      grid, ray,
      [&](float tmin, float& limit, auto&& leaf) { hgrid_detail::traverse(grid, ray, tmin, limit, leaf); },
      mailbox);
}

}  // namespace outcore
