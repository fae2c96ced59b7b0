// The every-hit walk (count_intersections, list_intersections) over one
// wide BVH: every leaf whose box the ray's segment may touch, tested with the
// lane tests of wide_bvh_kernels.h, each hit handed to a sink (a record, or
// only a count). Like the other kernels, templated on the lane type and
// compiled only in wide_bvh_trace_sse4.cpp and wide_bvh_trace_avx2.cpp.
//
// Thread-safety: pure functions over an immutable WideBvhView.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/bvh/wide_bvh_kernels.h"

namespace outcore::wide_kernels {

// Where all_hits_rays puts each hit: a record (append_hit is defined
// outside the SIMD-targeted files, wide_bvh_trace.h), or only a count.
// Templates on the lane type, like every kernel here, so that each SIMD
// file compiles its own copy under its own target.
template <class V>
struct RecordEveryHit {
  std::vector<RayHitRecord>& out;
  void operator()(uint32_t ray, const TrianglePacket& packet, uint32_t lane, const TriangleHit& h) const {
    append_hit(out, ray,
               {h.t, packet.geometry_id[lane], packet.primitive_id[lane], h.u, h.v,
                packet.triangle(lane).unit_normal()});
  }
};
template <class V>
struct CountEveryHit {
  uint32_t* counts;
  void operator()(uint32_t ray, const TrianglePacket&, uint32_t, const TriangleHit&) const { ++counts[ray]; }
};

// Visits every leaf of `tree` whose box the segment [tmin, tmax] may touch,
// in no particular order: an every-hit walk never shortens its segment, so
// the ordered walk's sorting and its pending-entry checks buy nothing. The
// node test is node_box_mask's, so the same leaves are met.
template <class V, class Leaf>
inline void traverse_every_leaf(const WideBvhView& tree, const BoxLanes<V>& box, float tmin, float tmax,
                                Leaf&& leaf) {
  if (tree.nodes.empty()) return;
  struct Item {
    uint32_t ref;        // node index, or a leaf's first slot
    uint32_t triangles;  // 0 for a node, else the leaf's count
  };
  std::array<Item, (kWideBvhWidth - 1) * kMaxBvhDepth + kWideBvhWidth> stack;
  uint32_t top = 0;
  uint32_t index = 0;
  while (true) {
    const WideBvhNode& node = tree.nodes[index];
    alignas(32) float entry[kWideBvhWidth];
    const uint32_t mask = node_box_mask<V>(node, box, tmin, tmax, entry);
    // Every child's memory asked for first (the walk waits on memory), then
    // inner children pushed and the leaves tested while the rest arrives.
    const uint32_t leaf_bits = mask & node.leaf_mask;
    for (uint32_t leaves = leaf_bits; leaves != 0; leaves &= leaves - 1)
      prefetch_lines(&tree.packets[node.child[__builtin_ctz(leaves)] / kPacketLanes], sizeof(TrianglePacket));
    for (uint32_t inner = mask & node.inner_mask; inner != 0; inner &= inner - 1) {
      const uint32_t child = node.child[__builtin_ctz(inner)];
      prefetch_lines(&tree.nodes[child], sizeof(WideBvhNode));
      stack[top++] = {child, 0};
    }
    for (uint32_t leaves = leaf_bits; leaves != 0; leaves &= leaves - 1) {
      const uint32_t k = static_cast<uint32_t>(__builtin_ctz(leaves));
      leaf(node.child[k], node.leaf_triangles[k]);
    }
    if (top == 0) return;
    index = stack[--top].ref;
  }
}

// Every hit of one ray in (tnear, tfar]: the any-hit walk that never stops
// and never shortens the segment, each hit handed to `sink`.
template <class V, class Lanes, class Sink>
void all_hits_rays(const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
                   const Sink& sink) {
  const TrianglePacket* packets = tree.packets.data();
  for (const uint32_t i : ray_ids) {
    const Ray& ray = rays[i];
    if (!(ray.tfar > ray.tnear)) continue;
    const BoxLanes<V> box(ray);
    Lanes lanes(ray);
    traverse_every_leaf<V>(tree, box, ray.tnear, ray.tfar, [&](uint32_t first, uint32_t count) {
      for_each_lane_group<V>(
          packets, first, count, [&](const TrianglePacket& packet, uint32_t lane, uint32_t valid) {
            for (uint32_t bits = lanes.candidates(packet, lane, valid, ray.tnear, ray.tfar); bits != 0;
                 bits &= bits - 1) {
              const auto bit = static_cast<uint32_t>(__builtin_ctz(bits));
              TriangleHit h;
              if (lanes.accept(packet, lane, bit, h)) sink(i, packet, lane + bit, h);
            }
            return false;
          });
    });
  }
}

}  // namespace outcore::wide_kernels
