// Ray packets for the wide BVH: closest hits of up to V::kWidth rays that
// leave one origin with the same watertight axis permutation (a camera's
// rays, in pixel order) traced together, one ray per lane: each node's and
// each triangle's data are fetched once for the packet, and the walk is
// decided once for it. Rays that do not form such a run take the single-ray
// walk (wide_bvh_kernels.h). Compiled like that header, once per lane type.
//
// Exact as the single-ray walk: a lane's box test is the same conservative
// slab test (margin kBoxMargin, a NaN slab distance constrains nothing), and
// a lane's triangle test is the scalar watertight test's IEEE operations in
// its order (the shared permutation makes the vertex rows the same for every
// lane), so t, u, v are bitwise the scalar test's; ties go by
// hit_is_better; the answers are bitwise the single-ray walk's (tested).
//
// Thread-safety: pure functions over an immutable WideBvhView.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>

#include "core/accel/bvh/wide_bvh_kernels.h"

namespace outcore::wide_kernels {

// Up to V::kWidth rays traced as one packet.
template <class V>
class WatertightPacket {
 public:
  using F = typename V::F;
  static constexpr uint32_t kWidth = V::kWidth;

  // Rays rays[ids[0..count)], which share the permutation of rays[ids[0]].
  WatertightPacket(const Ray* rays, const uint32_t* ids, uint32_t count, Hit* hits) : hits_(hits) {
    axes_ = WatertightTriangleTest::axes(rays[ids[0]].direction);
    alignas(32) float o[3][kWidth], inv[3][kWidth], po[3][kWidth], s[3][kWidth], tnear[kWidth];
    for (uint32_t lane = 0; lane < kWidth; ++lane) {
      const uint32_t id = ids[lane < count ? lane : 0];
      const Ray& ray = rays[id];
      const WatertightTriangleTest::Prepared p = WatertightTriangleTest::prepare(ray);
      for (int a = 0; a < 3; ++a) {
        o[a][lane] = ray.origin[a];
        inv[a][lane] = 1.0f / ray.direction[a];
      }
      po[0][lane] = p.ox;
      po[1][lane] = p.oy;
      po[2][lane] = p.oz;
      s[0][lane] = p.sx;
      s[1][lane] = p.sy;
      s[2][lane] = p.sz;
      tnear[lane] = ray.tnear;
      ids_[lane] = id;
      direction_[lane] = ray.direction;
      const Hit& best = hits[id];
      tmax_[lane] = ray.tfar < best.t ? ray.tfar : best.t;
      if (lane < count && tmax_[lane] > ray.tnear) active_ |= 1u << lane;
    }
    for (int a = 0; a < 3; ++a) {
      origin_[a] = V::load(o[a]);
      inverse_[a] = V::load(inv[a]);
      permuted_origin_[a] = V::load(po[a]);
      shear_[a] = V::load(s[a]);
    }
    tnear_ = V::load(tnear);
  }

  // Over one tree (a set of one) or the trees of a set, walking its top
  // level with the packet.
  void trace_set(const WideBvhSetView& set) {
    if (active_ == 0) return;
    if (set.trees.size() == 1) return trace_lanes(set.trees[0], active_);
    walk(
        set.top, active_,
        [&](uint32_t tree, uint32_t, uint32_t lanes) { trace_lanes(set.trees[tree], lanes); },
        [&](uint32_t tree) { prefetch_lines(set.trees[tree].nodes.data(), sizeof(WideBvhNode)); });
  }

  // Completes each lane's best (barycentrics, normal).
  void finish() {
    for (uint32_t lane = 0; lane < kWidth; ++lane) {
      if (found_packet_[lane] == nullptr) continue;
      Hit& best = hits_[ids_[lane]];
      best.u = found_hit_[lane].u;
      best.v = found_hit_[lane].v;
      best.normal = found_packet_[lane]->triangle(found_slot_lane_[lane]).unit_normal();
    }
  }

 private:
  void trace_lanes(const WideBvhView& tree, uint32_t lanes) {
    walk(
        tree.nodes, lanes,
        [&](uint32_t first, uint32_t count, uint32_t leaf_lanes) {
          test_leaf(tree.packets.data(), first, count, leaf_lanes);
        },
        [](uint32_t) {});
  }

  // The packet's walk of `nodes` for `lanes`, nearest entry first:
  // leaf(ref, count, lanes) for each leaf some lane may still hit.
  template <class Leaf, class PrefetchLeaf>
  void walk(std::span<const WideBvhNode> nodes, uint32_t lanes, Leaf&& leaf, PrefetchLeaf&& prefetch_leaf) {
    if (nodes.empty()) return;
    struct Item {
      uint32_t ref, triangles, lanes;
      float entry;  // the smallest entry of its lanes
    };
    std::array<Item, (kWideBvhWidth - 1) * kMaxBvhDepth + kWideBvhWidth> stack;
    uint32_t top = 0;
    stack[top++] = {0, 0, lanes, -std::numeric_limits<float>::infinity()};
    while (top > 0) {
      const Item item = stack[--top];
      if (!may_matter(item.lanes, item.entry)) continue;
      if (item.triangles != 0) {
        leaf(item.ref, item.triangles, item.lanes);
        continue;
      }
      const WideBvhNode& node = nodes[item.ref];
      const uint32_t base = top;
      for (uint32_t bits = node.child_mask(); bits != 0; bits &= bits - 1) {
        const auto k = static_cast<uint32_t>(__builtin_ctz(bits));
        float entry;
        const uint32_t hit_lanes = box_lanes(node, k, item.lanes, entry);
        if (hit_lanes == 0) continue;
        const Item child{node.child[k], node.leaf_triangles[k], hit_lanes, entry};
        if (child.triangles == 0) {
          prefetch_lines(&nodes[child.ref], sizeof(WideBvhNode));
        } else {
          prefetch_leaf(child.ref);
        }
        uint32_t j = top++;
        for (; j > base && stack[j - 1].entry < child.entry; --j) stack[j] = stack[j - 1];
        stack[j] = child;
      }
    }
  }

  // Whether any of `lanes` can still find a hit at or beyond `entry`.
  bool may_matter(uint32_t lanes, float entry) const {
    for (uint32_t bits = lanes; bits != 0; bits &= bits - 1) {
      if (entry <= tmax_[__builtin_ctz(bits)]) return true;
    }
    return false;
  }

  // The lanes of `lanes` whose segment may touch child k's box; entry: the
  // smallest lower bound of where they enter.
  uint32_t box_lanes(const WideBvhNode& node, uint32_t k, uint32_t lanes, float& entry) const {
    const F inf = V::set1(std::numeric_limits<float>::infinity());
    const F minus_inf = V::set1(-std::numeric_limits<float>::infinity());
    F lo = tnear_, hi = V::load_unaligned(tmax_);
    for (int a = 0; a < 3; ++a) {
      const F t0 = V::mul(V::sub(V::set1(node.lo[a][k]), origin_[a]), inverse_[a]);
      const F t1 = V::mul(V::sub(V::set1(node.hi[a][k]), origin_[a]), inverse_[a]);
      // Either distance NaN: the line lies in the slab's plane, no constraint.
      const F nan = V::bit_or(V::neq(t0, t0), V::neq(t1, t1));
      const F near = V::blend(V::min(t0, t1), minus_inf, nan);
      const F far = V::blend(V::max(t0, t1), inf, nan);
      lo = V::max(near, lo);
      hi = V::min(far, hi);
    }
    const F down = V::set1(bvh_detail::kWidenDown), up = V::set1(bvh_detail::kWidenUp);
    lo = V::min(V::mul(lo, down), V::mul(lo, up));
    hi = V::max(V::mul(hi, down), V::mul(hi, up));
    const uint32_t hit = lanes & V::mask(V::le(lo, hi));
    if (hit != 0) {
      alignas(32) float entries[kWidth];
      V::store(entries, lo);
      entry = std::numeric_limits<float>::infinity();
      for (uint32_t bits = hit; bits != 0; bits &= bits - 1)
        entry = std::min(entry, entries[__builtin_ctz(bits)]);
    }
    return hit;
  }

  void test_leaf(const TrianglePacket* packets, uint32_t first, uint32_t count, uint32_t lanes) {
    for (uint32_t slot = first; slot < first + count; ++slot) {
      const TrianglePacket& packet = packets[slot / kPacketLanes];
      const uint32_t lane_of_slot = slot % kPacketLanes;
      test_triangle(packet, lane_of_slot, lanes);
    }
  }

  // The watertight test of one triangle against every lane, as the scalar
  // test computes it for each ray.
  void test_triangle(const TrianglePacket& packet, uint32_t slot_lane, uint32_t lanes) {
    const auto vertex = [&](int v, int axis) { return V::set1(packet.coord[3 * v + axis][slot_lane]); };
    WatertightLaneHits<V> found;
    const uint32_t pass = watertight_lanes<V>(vertex, axes_, permuted_origin_, shear_, lanes, tnear_,
                                              V::load_unaligned(tmax_), found);
    if (pass == 0) return;
    const Triangle tri = packet.triangle(slot_lane);
    const uint32_t geometry_id = packet.geometry_id[slot_lane], primitive_id = packet.primitive_id[slot_lane];
    for (uint32_t bits = pass; bits != 0; bits &= bits - 1) {
      const auto lane = static_cast<uint32_t>(__builtin_ctz(bits));
      if (WatertightTriangleTest::in_plane(direction_[lane], tri)) continue;
      Hit& best = hits_[ids_[lane]];
      if (!hit_is_better(found.t[lane], geometry_id, primitive_id, best)) continue;
      const float inv = 1.0f / found.det[lane];
      best.t = found.t[lane];
      best.geometry_id = geometry_id;
      best.primitive_id = primitive_id;
      found_packet_[lane] = &packet;
      found_slot_lane_[lane] = slot_lane;
      found_hit_[lane] = {found.t[lane], found.v[lane] * inv, found.w[lane] * inv};
      tmax_[lane] = found.t[lane];  // inclusive: a tie may still win on its id
    }
  }

  Hit* hits_;
  WatertightTriangleTest::Axes axes_{};
  uint32_t active_ = 0;
  uint32_t ids_[kWidth];
  Vec3f direction_[kWidth];
  alignas(32) float tmax_[kWidth];
  F origin_[3], inverse_[3], permuted_origin_[3], shear_[3], tnear_;
  const TrianglePacket* found_packet_[kWidth] = {};
  uint32_t found_slot_lane_[kWidth] = {};
  TriangleHit found_hit_[kWidth] = {};
};

// The length of the run of rays from ray_ids[start] that may go as one
// packet: the same origin, bitwise, and the same watertight permutation.
template <uint32_t kWidth>
inline uint32_t packet_run(std::span<const uint32_t> ray_ids, std::size_t start, const Ray* rays) {
  const Ray& first = rays[ray_ids[start]];
  // Incoherent rays part at the first comparison, before any division.
  if (start + 1 >= ray_ids.size() || !(rays[ray_ids[start + 1]].origin == first.origin)) return 1;
  const WatertightTriangleTest::Axes axes = WatertightTriangleTest::axes(first.direction);
  uint32_t count = 1;
  while (count < kWidth && start + count < ray_ids.size()) {
    const Ray& next = rays[ray_ids[start + count]];
    if (!(next.origin == first.origin) || !(WatertightTriangleTest::axes(next.direction) == axes)) break;
    ++count;
  }
  return count;
}

// Closest hits with the watertight test: packets where rays form runs of at
// least half a packet, single rays elsewhere; over one tree (a set of one,
// without top level) or a brick set.
template <class V>
void intersect_watertight_coherent(const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                                   const Ray* rays, Hit* hits) {
  constexpr uint32_t kWidth = V::kWidth;
  std::size_t i = 0;
  while (i < ray_ids.size()) {
    const uint32_t run = packet_run<kWidth>(ray_ids, i, rays);
    if (run * 2 < kWidth) {
      intersect_set<V, WatertightLanes<V>>(set, ray_ids.subspan(i, run), rays, hits);
    } else {
      WatertightPacket<V> packet(rays, ray_ids.data() + i, run, hits);
      packet.trace_set(set);
      packet.finish();
    }
    i += run;
  }
}

}  // namespace outcore::wide_kernels
