// Traversal of an OctreeView for one ray, parametric in the manner of
// Revelles, Ureña & Lastra 2000 ("An efficient parametric algorithm for
// octree traversal"): no box is tested against the ray; at a node, the t at
// which the ray crosses its low, middle and high plane along each axis gives
// every child's interval of t directly (child k's part along axis a is
// [t_low, t_mid] or [t_mid, t_high], in the ray's travel order), and the
// children whose three parts overlap within [tmin, best hit] are visited
// front to back, by where they begin.
//
// Where this departs from the paper, and why: the paper picks the next child
// from a state table (first_node / new_node, with the index mirrored by the
// direction's signs; its published errata concern those index bits) and
// follows exactly one path at a tie. In float that is not conservative: a ray
// through a cell corner or edge may, by rounding, leave out a child it
// touches. Here every crossing is widened by kBoxMargin (as the kd-tree's
// and the grid's), so near a tie every child the ray may touch is kept, and
// the children are ordered by their widened starts instead of by the table
// (at most eight, usually one to four). Mirroring is not needed: the
// intervals come out of each axis's own travel direction. A ray parallel to
// an axis stays in the half (or halves, when on the middle plane) holding
// its origin. The walk stops taking a child that begins beyond the best
// hit, so a triangle spanning cells never ends it early with a farther hit.
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>

#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/accel/octree/octree.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace octree_detail {

inline constexpr float kInf = std::numeric_limits<float>::infinity();

// A node waiting on the stack: its index, box, and the widened t at which
// the ray may first be in it.
struct PendingCell {
  uint32_t node;
  float entry;
  Aabb box;
};

// The ray's widened parts of t in the lower and upper half of `box` along
// one axis.
struct HalfParts {
  float lower_start, lower_end, upper_start, upper_end;
};
inline HalfParts half_parts(const Ray& ray, float inverse_direction, int axis, float lo, float middle,
                            float hi) {
  const float o = ray.origin[axis], d = ray.direction[axis];
  if (d == 0.0f) {
    const bool in_lower = o <= middle, in_upper = o >= middle;
    return {in_lower ? -kInf : kInf, in_lower ? kInf : -kInf, in_upper ? -kInf : kInf,
            in_upper ? kInf : -kInf};
  }
  const float t_lo = (lo - o) * inverse_direction;
  const float t_mid = (middle - o) * inverse_direction;
  const float t_hi = (hi - o) * inverse_direction;
  // NaN: a direction so small its inverse overflowed, the origin on the
  // plane: the crossing time is unknown, so the part is unbounded there.
  auto down = [](float t) { return t != t ? -kInf : kd_detail::widen_down(t); };
  auto up = [](float t) { return t != t ? kInf : kd_detail::widen_up(t); };
  if (d > 0.0f) return {down(t_lo), up(t_mid), down(t_mid), up(t_hi)};
  return {down(t_mid), up(t_lo), down(t_hi), up(t_mid)};
}

// Calls leaf(first, count, limit) for the leaves the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf>
inline void traverse(const OctreeView& tree, const Ray& ray, float tmin, float& limit, Leaf&& leaf) {
  if (tree.nodes.empty()) return;
  const bvh_detail::BoxRay box_ray(ray);
  float segment_min, segment_max;
  if (!kd_detail::clip_to_bounds(tree.bounds, ray, box_ray, tmin, limit, segment_min, segment_max)) return;
  // Seven pending siblings a level at most, and the root.
  std::array<PendingCell, 7 * kMaxOctreeDepth + 1> stack;
  uint32_t top = 0;
  stack[top++] = {0, segment_min, tree.bounds};
  while (top > 0) {
    const PendingCell cell = stack[--top];
    if (cell.entry > limit) continue;
    const OctreeNode& node = tree.nodes[cell.node];
    if (node.is_leaf()) {
      if (node.count() != 0 && leaf(node.first(), node.count(), limit)) return;
      continue;
    }
    const Vec3f middle = octree_middle(cell.box);
    std::array<HalfParts, 3> parts;
    for (int a = 0; a < 3; ++a) {
      parts[a] = half_parts(ray, box_ray.inverse_direction[a], a, cell.box.lo[a], middle[a], cell.box.hi[a]);
    }
    // The children the segment may touch, nearest start first.
    std::array<std::pair<float, uint32_t>, 8> children;
    uint32_t found = 0;
    const float node_end = std::min(segment_max, limit);
    for (uint32_t k = 0; k < 8; ++k) {
      float start = cell.entry, end = node_end;
      for (int a = 0; a < 3; ++a) {
        const bool upper = (k >> a) & 1u;
        start = std::max(start, upper ? parts[a].upper_start : parts[a].lower_start);
        end = std::min(end, upper ? parts[a].upper_end : parts[a].lower_end);
      }
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
      stack[top++] = {node.first_child() + k, children[i].first, octree_child_box(cell.box, middle, k)};
    }
  }
}

}  // namespace octree_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test, class Mailbox = TriangleMailbox>
bool octree_closest_hit(const OctreeView& tree, const Ray& ray, Hit& best, Mailbox&& mailbox = {}) {
  return kd_detail::closest_hit<Test>(
      tree, ray, best,
      [&](float tmin, float& limit, auto&& leaf) { octree_detail::traverse(tree, ray, tmin, limit, leaf); },
      mailbox);
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test, class Mailbox = TriangleMailbox>
bool octree_any_hit(const OctreeView& tree, const Ray& ray, Mailbox&& mailbox = {}) {
  return kd_detail::any_hit<Test>(
      tree, ray,
      [&](float tmin, float& limit, auto&& leaf) { octree_detail::traverse(tree, ray, tmin, limit, leaf); },
      mailbox);
}

}  // namespace outcore
