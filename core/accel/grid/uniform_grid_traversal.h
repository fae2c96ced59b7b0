// Traversal of a UniformGridView for one ray: the 3D-DDA of grid_dda.h
// (conservative in float; it stops at the first cell whose best hit lies
// before the next boundary crossing, at the end of the segment, or at any
// hit for occlusion), testing each cell's triangles.
//
// Mailboxing: a triangle spanning several cells is tested once per ray —
// the leaf loop asks a small per-ray TriangleMailbox (on the stack, direct
// mapped) before testing; a triangle evicted from it is merely tested again,
// with the same answer.
//
// Thread-safety: pure functions over an immutable grid.
#pragma once

#include <cstdint>

#include "core/accel/grid/grid_dda.h"
#include "core/accel/grid/uniform_grid.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace grid_detail {

// Calls leaf(first, count, limit) for the cells the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf>
inline void traverse(const UniformGridView& grid, const Ray& ray, float tmin, float& limit, Leaf&& leaf) {
  if (grid.cell_starts.empty()) return;
  const uint32_t* starts = grid.cell_starts.data();
  walk_cells(grid, ray, bvh_detail::BoxRay(ray), tmin, limit, [&](uint32_t c) {
    const uint32_t first = starts[c], end = starts[c + 1];
    return first != end && leaf(first, end - first, limit);
  });
}

}  // namespace grid_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test, class Mailbox = TriangleMailbox>
bool grid_closest_hit(const UniformGridView& grid, const Ray& ray, Hit& best, Mailbox&& mailbox = {}) {
  return kd_detail::closest_hit<Test>(
      grid, ray, best,
      [&](float tmin, float& limit, auto&& leaf) { grid_detail::traverse(grid, ray, tmin, limit, leaf); },
      mailbox);
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test, class Mailbox = TriangleMailbox>
bool grid_any_hit(const UniformGridView& grid, const Ray& ray, Mailbox&& mailbox = {}) {
  return kd_detail::any_hit<Test>(
      grid, ray,
      [&](float tmin, float& limit, auto&& leaf) { grid_detail::traverse(grid, ray, tmin, limit, leaf); },
      mailbox);
}

}  // namespace outcore
