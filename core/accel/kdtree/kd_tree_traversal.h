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
// The walk itself (kd_detail::walk) is shared with the BSP tree: it is
// templated on the node type and on a Planes policy that says how the ray
// meets a node's plane (AxisPlanes here; bsp_tree_traversal.h's
// DirectionPlanes for planes of other orientations).
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <type_traits>

#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/kdtree/kd_tree.h"
#include "core/accel/kdtree/watertight_ref_lanes.h"
#include "core/accel/triangle_mailbox.h"
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

// How a ray's segment meets an inner node's plane (what a Planes policy
// reports): it stays on one side (parallel to the plane), lies in the plane
// (both children get the whole segment), or crosses it at [lo, hi] (a
// widened interval of t). `forward` says the child below comes first.
enum class PlaneCrossing { kBelowOnly, kAboveOnly, kInPlane, kCrosses };

// The kd-tree's planes: one axis per node, the crossing from the ray's
// reciprocal direction (the classic walk, float throughout).
struct AxisPlanes {
  const Ray& ray;
  const Vec3f& inverse_direction;

  PlaneCrossing cross(const KdNode& node, float& lo, float& hi, bool& forward) const {
    const int axis = node.axis();
    const float split = node.split();
    const float o = ray.origin[axis], d = ray.direction[axis];
    if (d == 0.0f) {
      // Parallel to the plane: the side of the origin, or both when in it.
      forward = true;
      if (o < split) return PlaneCrossing::kBelowOnly;
      if (o > split) return PlaneCrossing::kAboveOnly;
      return PlaneCrossing::kInPlane;
    }
    forward = d > 0.0f;
    const float t_split = (split - o) * inverse_direction[axis];
    if (t_split != t_split) return PlaneCrossing::kInPlane;  // 0 * inf: the ray lies in the plane
    lo = widen_down(t_split);
    hi = widen_up(t_split);
    return PlaneCrossing::kCrosses;
  }
};

// The walk shared by the kd-tree and the BSP tree (bsp_tree_traversal.h):
// Node has is_leaf(), above_child() (the child below is the next node),
// first() and count(); Planes::cross() says how the segment meets a node's
// plane. Calls leaf(first, count, limit) for the leaves the segment
// [t0, t1] may touch, front to back; leaf returns true to stop the walk (any
// hit). `limit` is the best hit so far (leaf lowers it). kMaxDepth bounds the
// tree's depth (one push per level: the stack cannot overflow).
// A part of the segment waiting on the stack: a node and its [tmin, tmax].
struct PendingPart {
  uint32_t node;
  float tmin, tmax;
};

// What the walk tells an observer at every node it enters (tests: the order
// of nodes, their parts of the segment and the stack); the default observes
// nothing and costs nothing.
struct NoWalkObserver {
  void enter(uint32_t /*node*/, float /*t0*/, float /*t1*/, std::span<const PendingPart> /*stack*/) const {}
};

template <uint32_t kMaxDepth, class Node, class Planes, class Leaf, class Observer = NoWalkObserver>
inline void walk(const Node* nodes, const Planes& planes, float t0, float t1, float& limit, Leaf&& leaf,
                 const Observer& observer = {}) {
  using Pending = PendingPart;
  std::array<Pending, kMaxDepth> stack;
  uint32_t top = 0;
  uint32_t index = 0;
  while (true) {
    if (t0 <= limit) {
      observer.enter(index, t0, t1, std::span<const Pending>(stack.data(), top));
      const Node& node = nodes[index];
      if (!node.is_leaf()) {
        const uint32_t below = index + 1, above = node.above_child();
        float lo = 0, hi = 0;
        bool forward = true;
        const PlaneCrossing crossing = planes.cross(node, lo, hi, forward);
        if (crossing == PlaneCrossing::kBelowOnly) {
          index = below;
          continue;
        }
        if (crossing == PlaneCrossing::kAboveOnly) {
          index = above;
          continue;
        }
        const uint32_t first = forward ? below : above;
        const uint32_t second = forward ? above : below;
        if (crossing == PlaneCrossing::kInPlane) {
          stack[top++] = {second, t0, t1};
          index = first;
        } else if (lo > t1) {
          index = first;
        } else if (hi < t0) {
          index = second;
        } else {
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

// The part of [tmin, limit] within `bounds` (widened, as box_hit), or false
// when the segment misses them.
inline bool clip_to_bounds(const Aabb& bounds, const Ray& ray, const bvh_detail::BoxRay& box_ray, float tmin,
                           float limit, float& segment_min, float& segment_max) {
  float entry;
  if (!bvh_detail::box_hit(box_ray, bounds, tmin, limit, entry)) return false;
  // box_hit's entry is a widened lower bound; the exit is recomputed the
  // same way.
  segment_min = std::max(tmin, entry);
  float exit_hi = limit;
  for (int axis = 0; axis < 3; ++axis) {
    const float t0 = (bounds.lo[axis] - ray.origin[axis]) * box_ray.inverse_direction[axis];
    const float t1 = (bounds.hi[axis] - ray.origin[axis]) * box_ray.inverse_direction[axis];
    if (t0 != t0 || t1 != t1) continue;
    exit_hi = std::min(exit_hi, widen_up(std::max(t0, t1)));
  }
  segment_max = exit_hi;
  return true;
}

// Calls leaf(first, count, limit) for the leaves the segment [tmin, limit]
// may touch, front to back; leaf returns true to stop the walk (any hit).
// `limit` is the best hit so far (leaf lowers it).
template <class Leaf, class Observer = NoWalkObserver>
inline void traverse(const KdTreeView& tree, const Ray& ray, float tmin, float& limit, Leaf&& leaf,
                     const Observer& observer = {}) {
  if (tree.nodes.empty()) return;
  const bvh_detail::BoxRay box_ray(ray);
  float segment_min, segment_max;
  if (!clip_to_bounds(tree.bounds, ray, box_ray, tmin, limit, segment_min, segment_max)) return;
  const AxisPlanes planes{ray, box_ray.inverse_direction};
  walk<kMaxKdDepth>(tree.nodes.data(), planes, segment_min, segment_max, limit, leaf, observer);
}

// A leaf's (a cell's) triangle references tested for one ray with Test:
// the watertight test four at a time on x86 (watertight_ref_lanes.h, its
// lanes prepared once per ray), the others, and a lone reference, one at a
// time. Bitwise the same hits either way.
struct NoRefLanes {
  template <class Prepared>
  explicit NoRefLanes(const Prepared&) {}
};
#if defined(__x86_64__) || defined(__i386__)
template <class Test>
using RefLanesFor =
    std::conditional_t<std::is_same_v<Test, WatertightTriangleTest>, WatertightRefLanes, NoRefLanes>;
#else
template <class Test>
using RefLanesFor = NoRefLanes;
#endif

template <class Test>
class RefTests {
 public:
  explicit RefTests(const Ray& ray) : prepared_(Test::prepare(ray)), lanes_(prepared_) {}

  // Tests triangles[refs[k]] for k < count that the mailbox admits over
  // (tnear, tfar], calling on_hit(triangle, hit) for each hit; on_hit may
  // lower tfar and returns true to stop (then so does test()).
  template <class Mailbox, class OnHit>
  bool test(const uint32_t* refs, uint32_t count, const Triangle* triangles, Mailbox& mailbox, float tnear,
            const float& tfar, OnHit&& on_hit) {
    if constexpr (!std::is_same_v<RefLanesFor<Test>, NoRefLanes>) {
      if (count > 1) return lanes_.test(refs, count, triangles, mailbox, tnear, tfar, on_hit);
    }
    for (uint32_t k = 0; k < count; ++k) {
      const uint32_t tri = refs[k];
      if (!mailbox.first_visit(tri)) continue;
      TriangleHit h;
      if (Test::hit(prepared_, triangles[tri], tnear, tfar, h) && on_hit(tri, h)) return true;
    }
    return false;
  }

 private:
  const typename Test::Prepared prepared_;
  [[no_unique_address]] RefLanesFor<Test> lanes_;
};

// Closest and any hit over the leaves (cells) a structure's traversal
// visits, shared by the kd-tree, the BSP tree and the grid:
// walk(tmin, limit, leaf) runs the structure's traverse(); the leaves'
// references index tree.refs; a reference the mailbox has seen is skipped
// (triangle_mailbox.h).
template <class Test, class View, class Walk, class Mailbox = NoMailbox>
bool closest_hit(const View& tree, const Ray& ray, Hit& best, Walk&& walk, Mailbox&& mailbox = Mailbox{}) {
  float limit = ray.tfar < best.t ? ray.tfar : best.t;
  if (!(limit > ray.tnear)) return false;
  RefTests<Test> tests(ray);
  uint32_t found = kInvalidId;
  TriangleHit found_hit{};
  walk(ray.tnear, limit, [&](uint32_t first, uint32_t count, float& best_t) {
    const auto on_hit = [&](uint32_t tri, const TriangleHit& h) {
      const BvhHitRecord& record = tree.records[tri];
      if (!hit_is_better(h.t, record.geometry_id, record.primitive_id, best)) return false;
      best.t = h.t;
      best.geometry_id = record.geometry_id;
      best.primitive_id = record.primitive_id;
      found = tri;
      found_hit = h;
      best_t = h.t;  // inclusive: a tie may still win on its id
      return false;
    };
    tests.test(&tree.refs[first], count, tree.triangles.data(), mailbox, ray.tnear, best_t, on_hit);
    return false;
  });
  if (found == kInvalidId) return false;
  best.u = found_hit.u;
  best.v = found_hit.v;
  best.normal = tree.records[found].normal;
  return true;
}

template <class Test, class View, class Walk, class Mailbox = NoMailbox>
bool any_hit(const View& tree, const Ray& ray, Walk&& walk, Mailbox&& mailbox = Mailbox{}) {
  float limit = ray.tfar;
  if (!(limit > ray.tnear)) return false;
  RefTests<Test> tests(ray);
  bool hit = false;
  walk(ray.tnear, limit, [&](uint32_t first, uint32_t count, float& best_t) {
    hit = tests.test(&tree.refs[first], count, tree.triangles.data(), mailbox, ray.tnear, best_t,
                     [](uint32_t, const TriangleHit&) { return true; });
    if (hit) best_t = -std::numeric_limits<float>::infinity();  // ends the walk
    return hit;
  });
  return hit;
}

}  // namespace kd_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better(). Returns whether best changed.
template <class Test>
bool kd_closest_hit(const KdTreeView& tree, const Ray& ray, Hit& best) {
  return kd_detail::closest_hit<Test>(tree, ray, best, [&](float tmin, float& limit, auto&& leaf) {
    kd_detail::traverse(tree, ray, tmin, limit, leaf);
  });
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test>
bool kd_any_hit(const KdTreeView& tree, const Ray& ray) {
  return kd_detail::any_hit<Test>(tree, ray, [&](float tmin, float& limit, auto&& leaf) {
    kd_detail::traverse(tree, ray, tmin, limit, leaf);
  });
}

}  // namespace outcore
