// Traversal of a BvhTreeView for one ray: closest hit (with the tie rule of
// hit_is_better) and any hit (stops at the first), templated on the triangle
// test (mt_triangle_test.h, watertight_triangle_test.h, double_triangle_test.h)
// so the hot loop has no virtual or indirect call, and on nothing else: a
// fixed stack of kMaxBvhDepth entries, no allocation.
//
// Robust box test (Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2)): each slab
// distance (box - origin) * (1 / direction) carries at most three roundings,
// so scaling the exit distance up and the entry distance down by 1 + 2*gamma(3)
// makes the test conservative with respect to the exact ray. The watertight
// tests also decide on rounded, transformed vertex coordinates, so they can
// report a hit for a ray whose exact line passes a few ulps (of the distance
// from the origin) outside the triangle — and so outside its box. The margin
// here, kBoxMargin = 2^-18 relative (64 float ulps), covers both; it costs
// nothing measurable. A slab with a NaN distance (origin on the slab plane,
// direction parallel to it) constrains nothing; infinite distances (zero
// direction component, origin outside the slab) cull as they should.
//
// Thread-safety: pure functions over an immutable tree.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/bvh/triangle_hit.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

namespace outcore {
namespace bvh_detail {

inline constexpr float kBoxMargin = 0x1p-18f;
inline constexpr float kWidenUp = 1.0f + kBoxMargin;
inline constexpr float kWidenDown = 1.0f - kBoxMargin;

struct BoxRay {
  Vec3f origin;
  Vec3f inverse_direction;
  explicit BoxRay(const Ray& ray)
      : origin(ray.origin),
        inverse_direction(1.0f / ray.direction.x, 1.0f / ray.direction.y, 1.0f / ray.direction.z) {}
};

// Conservative: true when the ray's segment [tmin, tmax] may touch the box;
// entry is a lower bound of where it enters.
inline bool box_hit(const BoxRay& ray, const Aabb& box, float tmin, float tmax, float& entry) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float lo = tmin, hi = tmax;
  for (int axis = 0; axis < 3; ++axis) {
    const float t0 = (box.lo[axis] - ray.origin[axis]) * ray.inverse_direction[axis];
    const float t1 = (box.hi[axis] - ray.origin[axis]) * ray.inverse_direction[axis];
    // A NaN is 0 * inf: the origin on a slab plane and the direction parallel
    // to it, so the whole line lies in the (closed) slab: no constraint.
    // (fmin/fmax would instead pick the other, infinite, distance and cull.)
    const bool in_plane = t0 != t0 || t1 != t1;
    const float near = in_plane ? -kInf : std::min(t0, t1);
    const float far = in_plane ? kInf : std::max(t0, t1);
    // Scaling (not adding |t| * margin) keeps infinities infinite, so a
    // zero direction component outside the slab still culls.
    lo = std::max(lo, std::min(near * kWidenDown, near * kWidenUp));
    hi = std::min(hi, std::max(far * kWidenDown, far * kWidenUp));
  }
  entry = lo;
  return lo <= hi;
}

// Visits the leaves whose boxes the segment [tmin, tmax] may touch, nearest
// entry first. leaf(first, count) returns true to stop; it may lower tmax.
template <class LeafFn>
inline void traverse(const BvhTreeView& tree, const Ray& ray, float tmin, float& tmax, LeafFn&& leaf) {
  if (tree.nodes.empty()) return;
  const BvhNode* nodes = tree.nodes.data();
  const BoxRay box_ray(ray);
  float entry;
  if (!box_hit(box_ray, nodes[0].bounds, tmin, tmax, entry)) return;
  struct Entry {
    uint32_t node;
    float entry;
  };
  std::array<Entry, kMaxBvhDepth> stack;
  uint32_t top = 0;
  uint32_t index = 0;
  while (true) {
    const BvhNode& node = nodes[index];
    if (node.is_leaf()) {
      if (leaf(node.index, node.count, tmax)) return;
    } else {
      float entry_l, entry_r;
      const bool hit_l = box_hit(box_ray, nodes[node.index].bounds, tmin, tmax, entry_l);
      const bool hit_r = box_hit(box_ray, nodes[node.index + 1].bounds, tmin, tmax, entry_r);
      if (hit_l && hit_r) {
        // Depth <= kMaxBvhDepth and one push per level: the stack cannot overflow.
        if (entry_r < entry_l) {
          stack[top++] = {node.index, entry_l};
          index = node.index + 1;
        } else {
          stack[top++] = {node.index + 1, entry_r};
          index = node.index;
        }
        continue;
      }
      if (hit_l || hit_r) {
        index = hit_l ? node.index : node.index + 1;
        continue;
      }
    }
    // Next deferred node that can still matter (tmax may have dropped).
    do {
      if (top == 0) return;
      --top;
    } while (stack[top].entry > tmax);
    index = stack[top].node;
  }
}

}  // namespace bvh_detail

// Closest hit of `ray` over (tnear, min(tfar, best.t)]: replaces best when a
// triangle beats it by hit_is_better() (so equal t goes to the smaller user
// id, whatever the traversal order). Returns whether best changed.
template <class Test>
bool bvh_closest_hit(const BvhTreeView& tree, const Ray& ray, Hit& best) {
  float tmax = ray.tfar < best.t ? ray.tfar : best.t;
  if (!(tmax > ray.tnear)) return false;
  const typename Test::Prepared prepared = Test::prepare(ray);
  const Triangle* triangles = tree.triangles.data();
  const BvhHitRecord* records = tree.records.data();
  uint32_t found = kInvalidId;
  TriangleHit found_hit{};
  bvh_detail::traverse(tree, ray, ray.tnear, tmax, [&](uint32_t first, uint32_t count, float& limit) {
    for (uint32_t k = first; k < first + count; ++k) {
      TriangleHit h;
      if (!Test::hit(prepared, triangles[k], ray.tnear, limit, h)) continue;
      if (!hit_is_better(h.t, records[k].geometry_id, records[k].primitive_id, best)) continue;
      best.t = h.t;
      best.geometry_id = records[k].geometry_id;
      best.primitive_id = records[k].primitive_id;
      found = k;
      found_hit = h;
      limit = h.t;  // inclusive: a tie at h.t may still win on its id
    }
    return false;
  });
  if (found == kInvalidId) return false;
  best.u = found_hit.u;
  best.v = found_hit.v;
  best.normal = records[found].normal;
  return true;
}

// Any hit of `ray` in (tnear, tfar]; stops at the first.
template <class Test>
bool bvh_any_hit(const BvhTreeView& tree, const Ray& ray) {
  float tmax = ray.tfar;
  if (!(tmax > ray.tnear)) return false;
  const typename Test::Prepared prepared = Test::prepare(ray);
  const Triangle* triangles = tree.triangles.data();
  bool hit = false;
  bvh_detail::traverse(tree, ray, ray.tnear, tmax, [&](uint32_t first, uint32_t count, float& limit) {
    for (uint32_t k = first; k < first + count; ++k) {
      TriangleHit h;
      if (Test::hit(prepared, triangles[k], ray.tnear, limit, h)) {
        hit = true;
        return true;
      }
    }
    return false;
  });
  return hit;
}

}  // namespace outcore
