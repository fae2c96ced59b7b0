// The top level of a brick set (WideBvhSetView): a wide BVH over the bricks'
// trees whose leaf children each name one tree, so that a ray walks the
// trees it may enter nearest first without testing every tree's box — the
// set serves any number of bricks at the cost of a two-level BVH, as a
// scene of instances does.
//
// Built per set (a few thousand bricks at most take well under a
// millisecond): 8-way nodes by repeated median splits of the trees' box
// centres along the widest centre axis. Bricks are disjoint spatial cells of
// similar size, where the median is as good as an SAH split.
//
// Thread-safety: a pure function.
#pragma once

#include <span>
#include <vector>

#include "core/accel/bvh/wide_bvh.h"
#include "core/geometry/aabb.h"

namespace outcore {

// Nodes[0] is the root; leaf child k of a node has leaf_triangles 1 and
// child = the index into `boxes` of its tree. Empty boxes are left out;
// no boxes, or only empty ones, give no nodes.
std::vector<WideBvhNode> build_wide_top_level(std::span<const Aabb> boxes);

}  // namespace outcore
