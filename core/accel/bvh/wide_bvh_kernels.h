// The wide BVH's hot loops, written once over a lane type V (SimdLanes4 or
// SimdLanes8, simd_lanes.h) and compiled twice: in wide_bvh_trace_sse4.cpp
// for the baseline and in wide_bvh_trace_avx2.cpp under the avx2 target. Only
// those two files include this header, each instantiating its own V, so no
// function is compiled for both targets.
//
// - Box test: the eight children's boxes of a node at once (two groups of
//   four with SSE). Conservative as bvh_traversal.h's box_hit (Ize 2013): the
//   same relative margin kBoxMargin, planes taken in the ray's octant order,
//   and a NaN slab distance (origin on the plane, direction parallel to it)
//   constrains nothing, by the operand order of min/max.
// - Leaf tests: a packet's triangles V::kWidth at a time. Watertight and
//   Moeller-Trumbore lanes compute each lane with the scalar test's IEEE
//   operations in the scalar test's order (watertight_triangle_test.h,
//   mt_triangle_test.h), so a lane's t, u, v are bitwise the scalar test's;
//   the rare lanes that need the watertight test's double fallback or its
//   in-plane check take the scalar code. Any other test (double) runs
//   scalar over the packet's lanes.
// - Traversal: ordered by entry distance, a fixed stack, nothing allocated;
//   any-hit stops at the first hit.
//
// Closest hits follow hit_is_better, so the answer does not depend on the
// order in which leaves are met: it is bitwise the binary tree's scalar
// answer (tested).
//
// Thread-safety: pure functions over an immutable WideBvhView.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>

#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/simd_lanes.h"
#include "core/accel/bvh/watertight_lanes.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/accel/bvh/wide_bvh_trace.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

namespace outcore::wide_kernels {

// Per ray, for the box tests: origin and inverse direction broadcast, and
// which of a node's rows (lo or hi) is the near plane on each axis.
template <class V>
struct BoxLanes {
  typename V::F origin[3], inverse[3];
  uint32_t near_row[3], far_row[3];  // float offsets into WideBvhNode's lo/hi block
  typename V::F widen_down, widen_up;

  explicit BoxLanes(const Ray& ray) {
    // The three divisions in one: each lane is the IEEE quotient 1 / d.
    alignas(16) float inverses[4];
    _mm_store_ps(inverses, _mm_div_ps(_mm_set1_ps(1.0f),
                                      _mm_setr_ps(ray.direction.x, ray.direction.y, ray.direction.z, 1.0f)));
    for (int axis = 0; axis < 3; ++axis) {
      const float inv = inverses[axis];
      origin[axis] = V::set1(ray.origin[axis]);
      inverse[axis] = V::set1(inv);
      const bool negative = std::signbit(inv);
      const uint32_t lo_row = axis * kWideBvhWidth, hi_row = (3 + axis) * kWideBvhWidth;
      near_row[axis] = negative ? hi_row : lo_row;
      far_row[axis] = negative ? lo_row : hi_row;
    }
    widen_down = V::set1(bvh_detail::kWidenDown);
    widen_up = V::set1(bvh_detail::kWidenUp);
  }
};

// Bit k set when the segment [tmin, tmax] may touch child k's box; entry[k]
// is a lower bound of where it enters. The margin is applied once, to the
// folded entry and exit: scaling outward, x -> min(x * down, x * up), is
// monotonic, so widening the largest near distance (or tmin) is widening each
// and taking the largest, only looser at tmin itself.
//
// Always inlined: GCC kept it a call in the stepped walk, and inlined the
// bunny's incoherent rays take 0.93-0.96x the time, the city's 0.96x
// (docs/BENCHMARKS.md, issue 23).
template <class V>
__attribute__((always_inline)) inline uint32_t node_box_mask(const WideBvhNode& node, const BoxLanes<V>& ray,
                                                             float tmin, float tmax, float* entry) {
  const float* rows = &node.lo[0][0];  // lo[3][8] then hi[3][8]
  uint32_t mask = 0;
  for (uint32_t group = 0; group < kWideBvhWidth; group += V::kWidth) {
    typename V::F lo = V::set1(tmin), hi = V::set1(tmax);
    for (int axis = 0; axis < 3; ++axis) {
      const typename V::F near =
          V::mul(V::sub(V::load(rows + ray.near_row[axis] + group), ray.origin[axis]), ray.inverse[axis]);
      const typename V::F far =
          V::mul(V::sub(V::load(rows + ray.far_row[axis] + group), ray.origin[axis]), ray.inverse[axis]);
      // A NaN distance keeps lo / hi: max and min return their second operand.
      lo = V::max(near, lo);
      hi = V::min(far, hi);
    }
    // Scaled, not offset, so infinities stay infinite.
    lo = V::min(V::mul(lo, ray.widen_down), V::mul(lo, ray.widen_up));
    hi = V::max(V::mul(hi, ray.widen_down), V::mul(hi, ray.widen_up));
    V::store(entry + group, lo);
    mask |= V::mask(V::le(lo, hi)) << group;
  }
  return mask & node.child_mask();
}

// Where child k of `mask` goes in the run of the mask's children that a
// walk pushes, farthest entry at the bottom (ties: the lower index lower), so
// that popping gives the nearest first: the count of children farther than
// k, and of those as far with a lower index. Compares, no branch on the
// entries (an insertion sort mispredicted on them: the bunny's incoherent
// rays took 1.07x the time with it, docs/BENCHMARKS.md, issue 23).
template <class V>
inline uint32_t push_position(const float* entry, uint32_t mask, uint32_t k) {
  const typename V::F at = V::set1(entry[k]);
  uint32_t farther = 0, as_far = 0;
  for (uint32_t group = 0; group < kWideBvhWidth; group += V::kWidth) {
    const typename V::F row = V::load(entry + group);
    farther |= V::mask(V::gt(row, at)) << group;
    as_far |= V::mask(V::eq(row, at)) << group;
  }
  return static_cast<uint32_t>(__builtin_popcount(farther & mask) +
                               __builtin_popcount(as_far & mask & ((1u << k) - 1u)));
}

// Calls group(packet, first_lane, valid_bits) for each run of V::kWidth lanes
// that holds slots of [first, first + count); valid_bits are relative to
// first_lane. Stops and returns true when group does.
template <class V, class Group>
inline bool for_each_lane_group(const TrianglePacket* packets, uint32_t first, uint32_t count,
                                Group&& group) {
  uint64_t slot = first;
  const uint64_t end = uint64_t{first} + count;
  while (slot < end) {
    const uint64_t start = slot - slot % V::kWidth;
    const uint32_t from = static_cast<uint32_t>(slot - start);
    const uint32_t to = static_cast<uint32_t>(std::min<uint64_t>(end - start, V::kWidth));
    const uint32_t valid = ((1u << to) - 1u) & ~((1u << from) - 1u);
    if (group(packets[start / kPacketLanes], static_cast<uint32_t>(start % kPacketLanes), valid)) return true;
    slot = start + V::kWidth;
  }
  return false;
}

// The watertight test on V::kWidth lanes. candidates() leaves the lanes
// that pass every float test (edge signs, det != 0, tnear < t <= tfar);
// accept() finishes one: the in-plane check and the barycentrics.
template <class V>
class WatertightLanes {
 public:
  // Prepared at the first leaf: many brick visits of a ray reach none.
  explicit WatertightLanes(const Ray& ray) : ray_(ray) {}

  uint32_t candidates(const TrianglePacket& packet, uint32_t lane, uint32_t valid, float tnear, float tfar) {
    if (!prepared_) prepare();
    const auto row = [&](int vertex, int axis) { return V::load(&packet.coord[3 * vertex + axis][lane]); };
    return watertight_lanes<V>(row, ray_lanes_.axes, ray_lanes_.origin, ray_lanes_.shear, valid,
                               V::set1(tnear), V::set1(tfar), hits_);
  }

  bool accept(const TrianglePacket& packet, uint32_t lane, uint32_t bit, TriangleHit& hit) const {
    if (WatertightTriangleTest::in_plane(ray_.direction, packet.triangle(lane + bit))) return false;
    hit = hits_.hit(bit);
    return true;
  }

 private:
  void prepare() {
    ray_lanes_.set(WatertightTriangleTest::prepare(ray_));
    prepared_ = true;
  }

  const Ray& ray_;
  bool prepared_ = false;
  WatertightRayLanes<V> ray_lanes_;
  WatertightLaneHits<V> hits_;
};

// Moeller-Trumbore on V::kWidth lanes, the scalar test's operations in order.
template <class V>
class MtLanes {
 public:
  explicit MtLanes(const Ray& ray) {
    for (int axis = 0; axis < 3; ++axis) {
      origin_[axis] = V::set1(ray.origin[axis]);
      direction_[axis] = V::set1(ray.direction[axis]);
    }
  }

  uint32_t candidates(const TrianglePacket& packet, uint32_t lane, uint32_t valid, float tnear, float tfar) {
    using F = typename V::F;
    const auto row = [&](int vertex, int axis) { return V::load(&packet.coord[3 * vertex + axis][lane]); };
    const F v0[3] = {row(0, 0), row(0, 1), row(0, 2)};
    F e1[3], e2[3], s[3];
    for (int a = 0; a < 3; ++a) {
      e1[a] = V::sub(row(1, a), v0[a]);
      e2[a] = V::sub(row(2, a), v0[a]);
      s[a] = V::sub(origin_[a], v0[a]);
    }
    const F* d = direction_;
    const F p[3] = {V::sub(V::mul(d[1], e2[2]), V::mul(d[2], e2[1])),
                    V::sub(V::mul(d[2], e2[0]), V::mul(d[0], e2[2])),
                    V::sub(V::mul(d[0], e2[1]), V::mul(d[1], e2[0]))};
    const F det = dot(e1, p);
    const F zero = V::set1(0.0f), one = V::set1(1.0f);
    uint32_t pass = valid & V::mask(V::neq(det, zero));
    if (pass == 0) return 0;
    const F inv = V::div(one, det);
    const F u = V::mul(dot(s, p), inv);
    pass &= V::mask(V::bit_and(V::ge(u, zero), V::le(u, one)));
    if (pass == 0) return 0;
    const F q[3] = {V::sub(V::mul(s[1], e1[2]), V::mul(s[2], e1[1])),
                    V::sub(V::mul(s[2], e1[0]), V::mul(s[0], e1[2])),
                    V::sub(V::mul(s[0], e1[1]), V::mul(s[1], e1[0]))};
    const F v = V::mul(dot(d, q), inv);
    const F t = V::mul(dot(e2, q), inv);
    pass &= V::mask(V::bit_and(V::bit_and(V::ge(v, zero), V::le(V::add(u, v), one)),
                               V::bit_and(V::gt(t, V::set1(tnear)), V::le(t, V::set1(tfar)))));
    if (pass != 0) {
      V::store(t_, t);
      V::store(u_, u);
      V::store(v_, v);
    }
    return pass;
  }

  bool accept(const TrianglePacket&, uint32_t, uint32_t bit, TriangleHit& hit) const {
    hit = {t_[bit], u_[bit], v_[bit]};
    return true;
  }

 private:
  static typename V::F dot(const typename V::F* a, const typename V::F* b) {
    return V::add(V::add(V::mul(a[0], b[0]), V::mul(a[1], b[1])), V::mul(a[2], b[2]));
  }
  typename V::F origin_[3], direction_[3];
  float t_[V::kWidth], u_[V::kWidth], v_[V::kWidth];
};

// Any scalar triangle test (the double reference) over a packet's lanes.
template <class V, class Test>
class ScalarLanes {
 public:
  explicit ScalarLanes(const Ray& ray) : prepared_(Test::prepare(ray)) {}

  uint32_t candidates(const TrianglePacket&, uint32_t, uint32_t valid, float tnear, float tfar) {
    tnear_ = tnear;
    tfar_ = tfar;
    return valid;
  }
  bool accept(const TrianglePacket& packet, uint32_t lane, uint32_t bit, TriangleHit& hit) const {
    return Test::hit(prepared_, packet.triangle(lane + bit), tnear_, tfar_, hit);
  }

 private:
  typename Test::Prepared prepared_;
  float tnear_ = 0, tfar_ = 0;
};

// Asks for the cache lines of [p, p + bytes) ahead of their use.
inline void prefetch_lines(const void* p, std::size_t bytes) {
  const char* c = static_cast<const char*>(p);
  for (std::size_t offset = 0; offset < bytes; offset += 64) _mm_prefetch(c + offset, _MM_HINT_T0);
}

// Visits the leaves of `nodes` whose boxes the segment [tmin, tmax] may
// touch, nearest entry first. leaf(ref, count, tmax) returns true to stop; it
// may lower tmax. prefetch_leaf(ref) asks for a leaf's data when it is pushed.
// The walk starts at node `root` (a subtree; 0 for the whole tree).
template <class V, class Leaf, class PrefetchLeaf>
inline void traverse_nodes(std::span<const WideBvhNode> nodes, const BoxLanes<V>& box, float tmin,
                           float& tmax, Leaf&& leaf, PrefetchLeaf&& prefetch_leaf, uint32_t root = 0) {
  if (nodes.empty()) return;
  struct Item {
    uint32_t ref;        // node index, or a leaf's first slot
    uint32_t triangles;  // 0 for a node, else the leaf's count
    float entry;
  };
  // Each level leaves at most 7 siblings pending, and depth <= kMaxBvhDepth.
  std::array<Item, (kWideBvhWidth - 1) * kMaxBvhDepth + kWideBvhWidth> stack;
  uint32_t top = 0;
  uint32_t index = root;
  while (true) {
    const WideBvhNode& node = nodes[index];
    alignas(32) float entry[kWideBvhWidth];
    const uint32_t mask = node_box_mask<V>(node, box, tmin, tmax, entry);
    if (mask != 0) {
      const uint32_t first = static_cast<uint32_t>(__builtin_ctz(mask));
      if ((mask & (mask - 1)) == 0 && (node.inner_mask & mask) != 0) {
        index = node.child[first];  // one inner child: no stack traffic
        prefetch_lines(&nodes[index], sizeof(WideBvhNode));
        continue;
      }
      // Push the hit children farthest first, so the nearest is on top
      // (each at its push_position); start fetching each, as the
      // walk is bound by memory latency.
      for (uint32_t bits = mask; bits != 0; bits &= bits - 1) {
        const uint32_t k = static_cast<uint32_t>(__builtin_ctz(bits));
        const Item item{node.child[k], node.leaf_triangles[k], entry[k]};
        if (item.triangles == 0) {
          prefetch_lines(&nodes[item.ref], sizeof(WideBvhNode));
        } else {
          prefetch_leaf(item.ref);
        }
        stack[top + push_position<V>(entry, mask, k)] = item;
      }
      top += static_cast<uint32_t>(__builtin_popcount(mask));
    }
    // Next pending item that can still matter (tmax may have dropped).
    while (true) {
      if (top == 0) return;
      const Item item = stack[--top];
      if (item.entry > tmax) continue;
      if (item.triangles == 0) {
        index = item.ref;
        break;
      }
      if (leaf(item.ref, item.triangles, tmax)) return;
    }
  }
}

// traverse_nodes over one tree: leaves are runs of triangle slots.
template <class V, class Leaf>
inline void traverse(const WideBvhView& tree, const BoxLanes<V>& box, float tmin, float& tmax, Leaf&& leaf,
                     uint32_t root = 0) {
  traverse_nodes<V>(
      tree.nodes, box, tmin, tmax, leaf,
      [&](uint32_t first_slot) {
        prefetch_lines(&tree.packets[first_slot / kPacketLanes], sizeof(TrianglePacket));
      },
      root);
}

// The closest hit of one ray, over one tree or several (a brick set): the
// per-ray constants are prepared once, the best hit carried across trees.
// As bvh_closest_hit: over (tnear, min(tfar, best.t)], replacing best when a
// triangle beats it by hit_is_better.
template <class V, class Lanes>
class ClosestHitSearch {
 public:
  ClosestHitSearch(const Ray& ray, Hit& best)
      : ray_(ray), best_(best), box_(ray), lanes_(ray), tmax_(ray.tfar < best.t ? ray.tfar : best.t) {}

  bool active() const { return tmax_ > ray_.tnear; }
  float tnear() const { return ray_.tnear; }
  float& tmax() { return tmax_; }

  // Never stops early (false): a nearer hit may lie in a later tree. From
  // node `root`: a subtree only.
  bool search(const WideBvhView& tree, uint32_t root = 0) {
    const TrianglePacket* packets = tree.packets.data();
    traverse(
        tree, box_, ray_.tnear, tmax_,
        [&](uint32_t first, uint32_t count, float& limit) {
          for_each_lane_group<V>(
              packets, first, count, [&](const TrianglePacket& packet, uint32_t lane, uint32_t valid) {
                for (uint32_t bits = lanes_.candidates(packet, lane, valid, ray_.tnear, limit); bits != 0;
                     bits &= bits - 1) {
                  const uint32_t bit = static_cast<uint32_t>(__builtin_ctz(bits));
                  TriangleHit h;
                  if (!lanes_.accept(packet, lane, bit, h)) continue;
                  const uint32_t geometry_id = packet.geometry_id[lane + bit];
                  const uint32_t primitive_id = packet.primitive_id[lane + bit];
                  if (!hit_is_better(h.t, geometry_id, primitive_id, best_)) continue;
                  best_.t = h.t;
                  best_.geometry_id = geometry_id;
                  best_.primitive_id = primitive_id;
                  found_packet_ = &packet;
                  found_lane_ = lane + bit;
                  found_hit_ = h;
                  limit = h.t;  // inclusive: a tie at h.t may still win on its id
                }
                return false;
              });
          return false;
        },
        root);
    return false;
  }

  // Completes best (barycentrics, normal); whether it changed.
  bool finish() {
    if (found_packet_ == nullptr) return false;
    best_.u = found_hit_.u;
    best_.v = found_hit_.v;
    best_.normal = found_packet_->triangle(found_lane_).unit_normal();
    return true;
  }

  const BoxLanes<V>& box() const { return box_; }

 private:
  const Ray& ray_;
  Hit& best_;
  BoxLanes<V> box_;
  Lanes lanes_;
  float tmax_;
  const TrianglePacket* found_packet_ = nullptr;
  uint32_t found_lane_ = 0;
  TriangleHit found_hit_{};
};

// Any hit of one ray in (tnear, tfar], over one tree or several.
template <class V, class Lanes>
class AnyHitSearch {
 public:
  explicit AnyHitSearch(const Ray& ray) : ray_(ray), box_(ray), lanes_(ray), tmax_(ray.tfar) {}

  bool active() const { return tmax_ > ray_.tnear; }
  float tnear() const { return ray_.tnear; }
  float& tmax() { return tmax_; }

  bool search(const WideBvhView& tree) {
    const TrianglePacket* packets = tree.packets.data();
    bool hit = false;
    traverse(tree, box_, ray_.tnear, tmax_, [&](uint32_t first, uint32_t count, float& limit) {
      hit = for_each_lane_group<V>(
          packets, first, count, [&](const TrianglePacket& packet, uint32_t lane, uint32_t valid) {
            for (uint32_t bits = lanes_.candidates(packet, lane, valid, ray_.tnear, limit); bits != 0;
                 bits &= bits - 1) {
              TriangleHit h;
              const auto bit = static_cast<uint32_t>(__builtin_ctz(bits));
              if (lanes_.accept(packet, lane, bit, h)) return true;
            }
            return false;
          });
      return hit;
    });
    return hit;
  }

  const BoxLanes<V>& box() const { return box_; }

 private:
  const Ray& ray_;
  BoxLanes<V> box_;
  Lanes lanes_;
  float tmax_;
};

// Searches the trees of a set that the ray may enter, nearest entry first,
// until search.search(tree) returns true; whether it did.
template <class V, class Search>
inline bool search_set(const WideBvhSetView& set, Search& search) {
  if (set.trees.size() == 1) return search.search(set.trees[0]);  // its root's boxes are the set's
  bool stopped = false;
  traverse_nodes<V>(
      set.top, search.box(), search.tnear(), search.tmax(),
      [&](uint32_t tree, uint32_t, float&) { return stopped = search.search(set.trees[tree]); },
      [&](uint32_t tree) { prefetch_lines(set.trees[tree].nodes.data(), sizeof(WideBvhNode)); });
  return stopped;
}

template <class V, class Lanes>
void intersect_set(const WideBvhSetView& set, std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) {
  for (const uint32_t i : ray_ids) {
    ClosestHitSearch<V, Lanes> search(rays[i], hits[i]);
    if (!search.active()) continue;
    search_set<V>(set, search);
    search.finish();
  }
}

template <class V, class Lanes>
void occluded_set(const WideBvhSetView& set, std::span<const uint32_t> ray_ids, const Ray* rays,
                  uint8_t* occluded) {
  for (const uint32_t i : ray_ids) {
    if (occluded[i] != 0) continue;
    AnyHitSearch<V, Lanes> search(rays[i]);
    if (!search.active()) continue;
    if (search_set<V>(set, search)) occluded[i] = 1;
  }
}

}  // namespace outcore::wide_kernels
