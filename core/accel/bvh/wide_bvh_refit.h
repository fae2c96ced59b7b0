// Refitting a WideBvh (wide_bvh.h) after its triangles moved, and the
// surface-area cost that says when a refitted tree has degraded enough to be
// built again (the dynamic layer's meshes and instance top levels,
// core/dynamic/).
//
// A refit keeps the tree's shape and recomputes every box bottom-up from
// what the slots now hold: inner children always follow their parent, so one
// pass over the nodes in reverse order sees every child before its parent.
// The boxes are the exact float bounds of the triangles, as a fresh build
// computes them, so a refitted tree answers exactly as a fresh build of the
// same triangles does (only its speed differs).
//
// Thread-safety: pure functions over the tree they are given.
#pragma once

#include <cstdint>
#include <span>

#include "core/accel/bvh/wide_bvh.h"
#include "core/geometry/aabb.h"

namespace outcore {

// Recomputes every child box of `tree` from the triangles in its packets.
void refit_wide_bvh(WideBvh& tree);

// Recomputes the boxes of a top level whose leaf children name entries of
// `leaf_boxes` (wide_bvh_top_level.h's layout: leaf child k has child =
// index into leaf_boxes).
void refit_wide_top_level(std::span<WideBvhNode> nodes, std::span<const Aabb> leaf_boxes);

// The tree's surface-area cost relative to its root box: the expected
// number of node visits (1 per inner node entered) plus packet tests (1 per
// packet a leaf spans) of a ray through the root box, each weighted by the
// probability that a random ray through the root meets its box (area ratio).
// 0 for an empty tree. Comparable across refits of one tree, and with a fresh
// build of the same triangles.
double wide_bvh_sah_cost(std::span<const WideBvhNode> nodes);

}  // namespace outcore
