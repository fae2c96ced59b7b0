// Traversal of a KdTreeView for one ray, front to back with a fixed stack, as
// the classic kd-tree walk: the ray's segment is clipped to the tree's
// bounds; at an inner node the ray's t at the split plane decides whether the
// segment stays on the side it starts on, crosses over (the far child is
// pushed with its part of the segment, the near child taken with the rest) or
// starts beyond it; at a leaf its triangles are tested; the walk stops at the
// first leaf whose best hit lies inside that leaf's part of the segment (a
// triangle spanning several leaves must not end it early with a farther
// hit): the stack is popped, and parts that begin beyond the best hit are
// dropped. Templated on the triangle test (no virtual or indirect call).
//
// Conservative in float: the split distance is widened by kBoxMargin (the
// bvh's relative margin) on both sides, so a ray crossing near a plane
// visits both cells; a ray lying in a split plane (0 * inf) visits both with
// its whole segment; a ray parallel to a plane visits the side its origin is
// on. A cell's part starts at the widened-down crossing, so a hit found
// just past a plane (in the widened part of the previous cell), or a tie at
// a vertex on the plane, never hides a nearer or equal one in the next cell.
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/kdtree/kd_tree.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace kd_detail {

inline float widen_down(float t) {
  return std::min(t * bvh_detail::kWidenDown, t * bvh_detail::kWidenUp);
}
inline float widen_up(float t) {
  return std::max(t * bvh_detail::kWidenDown, t * bvh_detail::kWidenUp);
}

// Calls leaf(first, count, limit) for the leaves the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf>
inline void traverse(const KdTreeView& tree, const Ray& ray, float tmin, float& limit, Leaf&& leaf) {
  if (tree.nodes.empty()) return;
  float entry;
  const bvh_detail::BoxRay box_ray(ray);
  if (!bvh_detail::box_hit(box_ray, tree.bounds, tmin, limit, entry)) return;
  // The segment within the bounds (box_hit's entry is a widened lower bound;
  // the exit is recomputed the same way).
  float segment_min = std::max(tmin, entry), segment_max = limit;
  {
    float exit_hi = limit;
    for (int axis = 0; axis < 3; ++axis) {
      const float t0 = (tree.bounds.lo[axis] - ray.origin[axis]) * box_ray.inverse_direction[axis];
      const float t1 = (tree.bounds.hi[axis] - ray.origin[axis]) * box_ray.inverse_direction[axis];
      if (t0 != t0 || t1 != t1) continue;
      exit_hi = std::min(exit_hi, widen_up(std::max(t0, t1)));
    }
    segment_max = exit_hi;
  }
  struct Pending {
    uint32_t node;
    float tmin, tmax;
  };
  std::array<Pending, kMaxKdDepth> stack;
  uint32_t top = 0;
  uint32_t index = 0;
  float t0 = segment_min, t1 = segment_max;
  const KdNode* nodes = tree.nodes.data();
  while (true) {
    if (t0 <= limit) {
      const KdNode& node = nodes[index];
      if (!node.is_leaf()) {
        const int axis = node.axis();
        const float split = node.split();
        const float o = ray.origin[axis], d = ray.direction[axis];
        const uint32_t below = index + 1, above = node.above_child();
        if (d == 0.0f) {
          // Parallel to the plane: the side of the origin, or both when in it.
          if (o < split) {
            index = below;
          } else if (o > split) {
            index = above;
          } else {
            stack[top++] = {above, t0, t1};
            index = below;
          }
          continue;
        }
        const uint32_t first = d > 0.0f ? below : above;
        const uint32_t second = d > 0.0f ? above : below;
        const float t_split = (split - o) * box_ray.inverse_direction[axis];
        if (t_split != t_split) {  // 0 * inf: the ray lies in the plane
          stack[top++] = {second, t0, t1};
          index = first;
          continue;
        }
        const float lo = widen_down(t_split), hi = widen_up(t_split);
        if (lo > t1) {
          index = first;
        } else if (hi < t0) {
          index = second;
        } else {
          // Depth <= kMaxKdDepth and one push per level: no overflow.
          stack[top++] = {second, std::max(t0, lo), t1};
          index = first;
          t1 = std::min(t1, hi);
        }
        continue;
      }
      if (leaf(node.first(), node.count(), limit)) return;
    }
    // Next pending part that can still matter. The pending parts are nearest
    // on top, so once the top one begins beyond the best hit, all do: this is
    // where the walk stops at the first leaf whose hit lies within its own
    // part (a part's start is the previous part's end, both widened).
    while (true) {
      if (top == 0) return;
      const Pending pending = stack[--top];
      if (pending.tmin > limit) continue;
      index = pending.node;
      t0 = pending.tmin;
      t1 = pending.tmax;
      break;
    }
  }
}

}  // namespace kd_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test>
bool kd_closest_hit(const KdTreeView& tree, const Ray& ray, Hit& best) {
  float limit = ray.tfar < best.t ? ray.tfar : best.t;
  if (!(limit > ray.tnear)) return false;
  const typename Test::Prepared prepared = Test::prepare(ray);
  uint32_t found = kInvalidId;
  TriangleHit found_hit{};
  kd_detail::traverse(tree, ray, ray.tnear, limit, [&](uint32_t first, uint32_t count, float& best_t) {
    for (uint32_t k = first; k < first + count; ++k) {
      const uint32_t tri = tree.refs[k];
      TriangleHit h;
      if (!Test::hit(prepared, tree.triangles[tri], ray.tnear, best_t, h)) continue;
      const BvhHitRecord& record = tree.records[tri];
      if (!hit_is_better(h.t, record.geometry_id, record.primitive_id, best)) continue;
      best.t = h.t;
      best.geometry_id = record.geometry_id;
      best.primitive_id = record.primitive_id;
      found = tri;
      found_hit = h;
      best_t = h.t;  // inclusive: a tie may still win on its id
    }
    return false;
  });
  if (found == kInvalidId) return false;
  best.u = found_hit.u;
  best.v = found_hit.v;
  best.normal = tree.records[found].normal;
  return true;
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test>
bool kd_any_hit(const KdTreeView& tree, const Ray& ray) {
  float limit = ray.tfar;
  if (!(limit > ray.tnear)) return false;
  const typename Test::Prepared prepared = Test::prepare(ray);
  bool hit = false;
  kd_detail::traverse(tree, ray, ray.tnear, limit, [&](uint32_t first, uint32_t count, float& best_t) {
    for (uint32_t k = first; k < first + count; ++k) {
      TriangleHit h;
      if (Test::hit(prepared, tree.triangles[tree.refs[k]], ray.tnear, best_t, h)) {
        hit = true;
        best_t = -std::numeric_limits<float>::infinity();  // ends the walk
        return true;
      }
    }
    return false;
  });
  return hit;
}

}  // namespace outcore
