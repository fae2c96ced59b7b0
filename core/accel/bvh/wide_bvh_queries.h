// The bvh brick's closest-point query (brick_queries.h) as a walk of its
// wide tree: children nearest first, a box farther than the best point so
// far skipped (<=, so a tie with a smaller id is still found); distances in
// float64. Scalar, one point at a time. (Every hit runs on the SIMD kernels:
// wide_bvh_every_hit_kernels.h, all_hits_rays.)
//
// Thread-safety: pure functions over an immutable view.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/brick_queries.h"
#include "core/accel/bvh/wide_bvh.h"

namespace outcore {

namespace wide_bvh_queries_detail {

// Every child of a node may be pushed: 7 waiting per level at most.
inline constexpr uint32_t kStackSize = kMaxBvhDepth * (kWideBvhWidth - 1) + 1;

// Calls fn(triangle, geometry_id, primitive_id) for each triangle of leaf
// child k of `node` (padding slots skipped).
template <class Fn>
void for_each_leaf_triangle(const WideBvhView& tree, const WideBvhNode& node, uint32_t k, Fn&& fn) {
  for (uint32_t slot = node.child[k]; slot < node.child[k] + node.leaf_triangles[k]; ++slot) {
    const TrianglePacket& packet = tree.packets[slot / kPacketLanes];
    const uint32_t lane = slot % kPacketLanes;
    if (packet.primitive_id[lane] == kInvalidId) continue;
    fn(packet.triangle(lane), packet.geometry_id[lane], packet.primitive_id[lane]);
  }
}

}  // namespace wide_bvh_queries_detail

inline void wide_bvh_closest_points(const WideBvhView& tree, std::span<const uint32_t> point_ids,
                                    const Vec3f* points, ClosestPoint* best) {
  using namespace wide_bvh_queries_detail;
  if (tree.nodes.empty()) return;
  struct Entry {
    uint32_t node;
    double distance_squared;
  };
  Entry stack[kStackSize];
  for (const uint32_t i : point_ids) {
    const Vec3d p(points[i]);
    ClosestPoint& answer = best[i];
    uint32_t size = 0;
    stack[size++] = {0, 0.0};
    while (size > 0) {
      const Entry entry = stack[--size];
      if (entry.distance_squared > answer.distance_squared) continue;
      const WideBvhNode& node = tree.nodes[entry.node];
      Entry inner[kWideBvhWidth];
      uint32_t inner_count = 0;
      for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
        const uint8_t bit = uint8_t{1} << k;
        if ((node.child_mask() & bit) == 0) continue;
        const double d2 = distance_squared_to_box(p, node.box(k));
        if (d2 > answer.distance_squared) continue;
        if ((node.inner_mask & bit) != 0) {
          inner[inner_count++] = {node.child[k], d2};
          continue;
        }
        for_each_leaf_triangle(
            tree, node, k, [&](const Triangle& tri, uint32_t geometry, uint32_t primitive) {
              const TrianglePoint found = closest_point_on_triangle(p, tri);
              if (!closest_is_better(found.distance_squared, geometry, primitive, answer)) return;
              answer = {found.distance_squared,      Vec3f(found.point),          geometry,         primitive,
                        static_cast<float>(found.u), static_cast<float>(found.v), tri.unit_normal()};
            });
      }
      // Nearest on top of the stack: farthest pushed first (insertion sort of
      // at most 8, descending).
      for (uint32_t k = 1; k < inner_count; ++k) {
        const Entry entry_k = inner[k];
        uint32_t j = k;
        for (; j > 0 && inner[j - 1].distance_squared < entry_k.distance_squared; --j)
          inner[j] = inner[j - 1];
        inner[j] = entry_k;
      }
      for (uint32_t k = 0; k < inner_count; ++k) stack[size++] = inner[k];
    }
  }
}

}  // namespace outcore
