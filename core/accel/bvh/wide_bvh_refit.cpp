#include "core/accel/bvh/wide_bvh_refit.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cassert>

namespace outcore {
namespace {

Aabb node_bounds(const WideBvhNode& node) {
  Aabb box;
  const uint8_t used = node.child_mask();
  for (uint32_t k = 0; k < kWideBvhWidth; ++k)
    if ((used >> k) & 1u) box.extend(node.box(k));
  return box;
}

Aabb leaf_bounds(std::span<const TrianglePacket> packets, uint32_t first_slot, uint32_t count) {
  Aabb box;
  for (uint32_t s = first_slot; s < first_slot + count; ++s)
    box.extend(packets[s / kPacketLanes].triangle(s % kPacketLanes).bounds());
  return box;
}

// Leaf children first, all nodes at once (they read only the leaves' own
// triangles); then inner children bottom-up, which need their child's boxes
// and cost a union of eight boxes each.
template <typename LeafBox>
void refit_nodes(std::span<WideBvhNode> nodes, const LeafBox& leaf_box) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nodes.size(), 256), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      WideBvhNode& node = nodes[i];
      for (uint32_t k = 0; k < kWideBvhWidth; ++k)
        if ((node.leaf_mask >> k) & 1u) node.set_box(k, leaf_box(node, k));
    }
  });
  for (std::size_t i = nodes.size(); i-- > 0;) {
    WideBvhNode& node = nodes[i];
    for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
      if ((node.inner_mask >> k) & 1u) {
        assert(node.child[k] > i && node.child[k] < nodes.size());
        node.set_box(k, node_bounds(nodes[node.child[k]]));
      }
    }
  }
}

}  // namespace

void refit_wide_bvh(WideBvh& tree) {
  const std::span<const TrianglePacket> packets = tree.packets;
  refit_nodes(tree.nodes, [&](const WideBvhNode& node, uint32_t k) {
    return leaf_bounds(packets, node.child[k], node.leaf_triangles[k]);
  });
}

void refit_wide_top_level(std::span<WideBvhNode> nodes, std::span<const Aabb> leaf_boxes) {
  refit_nodes(nodes, [&](const WideBvhNode& node, uint32_t k) {
    assert(node.child[k] < leaf_boxes.size());
    return leaf_boxes[node.child[k]];
  });
}

double wide_bvh_sah_cost(std::span<const WideBvhNode> nodes) {
  if (nodes.empty()) return 0.0;
  const double root_area = node_bounds(nodes[0]).half_area();
  if (!(root_area > 0.0)) return 0.0;
  double cost = 1.0;  // the root
  for (const WideBvhNode& node : nodes) {
    for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
      const double p = node.box(k).half_area() / root_area;
      if ((node.inner_mask >> k) & 1u) {
        cost += p;
      } else if ((node.leaf_mask >> k) & 1u) {
        const uint32_t first = node.child[k], last = first + node.leaf_triangles[k] - 1;
        cost += p * (last / kPacketLanes - first / kPacketLanes + 1);
      }
    }
  }
  return cost;
}

}  // namespace outcore
