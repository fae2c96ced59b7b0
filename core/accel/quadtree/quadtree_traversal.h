// Traversal of a QuadtreeView for one ray, front to back in the plane with
// each cell's extent along the flat axis as a bound: at an inner node the
// ray's crossings of the low, middle and high lines along u and v give each
// child's interval of t in the plane (as the octree's parametric walk,
// octree_traversal.h, on two axes), which is cut to the t at which the ray
// is within the child's own extent along w (the slab its triangles reach);
// the children whose three parts overlap within [tmin, best hit] are visited
// by where they begin. A ray passing above a terrain cell's triangles thus
// leaves it without a test, and a ray along w (looking down) enters only
// the columns under it.
//
// Conservative in float as the octree's walk: every crossing, the slab's
// included, is widened by kBoxMargin, so near a tie every child the ray may
// touch is kept; a ray parallel to w is in a child's slab when its origin
// lies within it (closed). The walk stops taking a child that begins beyond
// the best hit, so a triangle spanning cells never ends it early with a
// farther hit.
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/accel/octree/octree_traversal.h"
#include "core/accel/quadtree/quadtree.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace quadtree_detail {

using octree_detail::kInf;

// A node waiting on the stack: its index, box, and the widened t at which
// the ray may first be in it.
struct PendingCell {
  uint32_t node;
  float entry;
  Aabb box;
};

// The widened t at which the ray is within [lo, hi] along w.
inline void slab_part(const Ray& ray, float inverse_direction, int w, float lo, float hi, float& start,
                      float& end) {
  const float o = ray.origin[w], d = ray.direction[w];
  if (d == 0.0f) {
    const bool inside = lo <= o && o <= hi;
    start = inside ? -kInf : kInf;
    end = inside ? kInf : -kInf;
    return;
  }
  const float t_lo = (lo - o) * inverse_direction, t_hi = (hi - o) * inverse_direction;
  const float first = d > 0.0f ? t_lo : t_hi, last = d > 0.0f ? t_hi : t_lo;
  // NaN (an inverse that overflowed, the origin on the plane): unbounded.
  start = first != first ? -kInf : kd_detail::widen_down(first);
  end = last != last ? kInf : kd_detail::widen_up(last);
}

// Calls leaf(first, count, limit) for the leaves the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf>
inline void traverse(const QuadtreeView& tree, const Ray& ray, float tmin, float& limit, Leaf&& leaf) {
  if (tree.nodes.empty()) return;
  const bvh_detail::BoxRay box_ray(ray);
  float segment_min, segment_max;
  if (!kd_detail::clip_to_bounds(tree.bounds, ray, box_ray, tmin, limit, segment_min, segment_max)) return;
  const QuadtreeAxes axes = quadtree_axes(tree.bounds);
  const float inverse_u = box_ray.inverse_direction[axes.u], inverse_v = box_ray.inverse_direction[axes.v];
  const float inverse_w = box_ray.inverse_direction[axes.w];
  // Three pending siblings a level at most, and the root.
  std::array<PendingCell, 3 * kMaxQuadtreeDepth + 1> stack;
  uint32_t top = 0;
  stack[top++] = {0, segment_min, tree.bounds};
  while (top > 0) {
    const PendingCell cell = stack[--top];
    if (cell.entry > limit) continue;
    const QuadtreeNode& node = tree.nodes[cell.node];
    if (node.is_leaf()) {
      if (node.count() != 0 && leaf(node.first(), node.count(), limit)) return;
      continue;
    }
    const float middle_u = quadtree_middle(cell.box, axes.u), middle_v = quadtree_middle(cell.box, axes.v);
    const octree_detail::HalfParts along_u =
        octree_detail::half_parts(ray, inverse_u, axes.u, cell.box.lo[axes.u], middle_u, cell.box.hi[axes.u]);
    const octree_detail::HalfParts along_v =
        octree_detail::half_parts(ray, inverse_v, axes.v, cell.box.lo[axes.v], middle_v, cell.box.hi[axes.v]);
    // The children the segment may touch, nearest start first.
    std::array<std::pair<float, uint32_t>, 4> children;
    uint32_t found = 0;
    const float node_end = std::min(segment_max, limit);
    for (uint32_t k = 0; k < 4; ++k) {
      // The plane first (cheap, and rules out the children off the ray's
      // path), then the child's height slab.
      float start = std::max({cell.entry, k & 1u ? along_u.upper_start : along_u.lower_start,
                              k & 2u ? along_v.upper_start : along_v.lower_start});
      float end = std::min({node_end, k & 1u ? along_u.upper_end : along_u.lower_end,
                            k & 2u ? along_v.upper_end : along_v.lower_end});
      if (!(start <= end)) continue;
      const QuadtreeNode& child = tree.nodes[node.first_child() + k];
      if (child.is_empty()) continue;
      float slab_start, slab_end;
      slab_part(ray, inverse_w, axes.w, child.w_lo, child.w_hi, slab_start, slab_end);
      start = std::max(start, slab_start);
      end = std::min(end, slab_end);
      if (!(start <= end)) continue;
      uint32_t at = found++;
      while (at > 0 && children[at - 1].first > start) {
        children[at] = children[at - 1];
        --at;
      }
      children[at] = {start, k};
    }
    // Farthest first onto the stack, so the nearest is taken next.
    for (uint32_t i = found; i-- > 0;) {
      const uint32_t k = children[i].second;
      stack[top++] = {node.first_child() + k, children[i].first,
                      quadtree_child_box(cell.box, axes, middle_u, middle_v, k)};
    }
  }
}

}  // namespace quadtree_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test, class Mailbox = TriangleMailbox>
bool quadtree_closest_hit(const QuadtreeView& tree, const Ray& ray, Hit& best, Mailbox&& mailbox = {}) {
  return kd_detail::closest_hit<Test>(
      tree, ray, best,
      [&](float tmin, float& limit, auto&& leaf) { quadtree_detail::traverse(tree, ray, tmin, limit, leaf); },
      mailbox);
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test, class Mailbox = TriangleMailbox>
bool quadtree_any_hit(const QuadtreeView& tree, const Ray& ray, Mailbox&& mailbox = {}) {
  return kd_detail::any_hit<Test>(
      tree, ray,
      [&](float tmin, float& limit, auto&& leaf) { quadtree_detail::traverse(tree, ray, tmin, limit, leaf); },
      mailbox);
}

}  // namespace outcore
