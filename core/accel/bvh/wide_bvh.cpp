#include "core/accel/bvh/wide_bvh.h"

#include <string>

namespace outcore {

Status WideBvhView::validate() const {
  if (nodes.empty()) {
    if (!packets.empty()) return invalid_argument("wide bvh: triangles but no nodes");
    return Status::Ok();
  }
  // Children strictly after their parent: no cycles. Every node has a child
  // and every path ends in a leaf of at least one triangle, so counting the
  // slots the leaves cover bounds the walk even over shared children.
  struct Item {
    uint32_t node, depth;
  };
  Item stack[kWideBvhWidth * kMaxBvhDepth + kWideBvhWidth];
  std::size_t size = 0;
  stack[size++] = {0, 1};
  uint64_t covered = 0;
  const uint64_t slots = slot_count();
  while (size > 0) {
    const Item item = stack[--size];
    const WideBvhNode& node = nodes[item.node];
    const std::string where = "wide bvh: node " + std::to_string(item.node);
    if ((node.inner_mask & node.leaf_mask) != 0 || node.child_mask() == 0) {
      return invalid_argument(where + " has malformed child masks");
    }
    for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
      const uint32_t bit = 1u << k;
      if ((node.leaf_mask & bit) != 0) {
        const uint32_t count = node.leaf_triangles[k];
        if (count == 0 || uint64_t{node.child[k]} + count > slots) {
          return invalid_argument(where + " has a leaf past the triangles");
        }
        covered += count;
        if (covered > slots) return invalid_argument("wide bvh: leaves overlap");
      } else if ((node.inner_mask & bit) != 0) {
        if (node.child[k] <= item.node || node.child[k] >= nodes.size()) {
          return invalid_argument(where + " has children out of range");
        }
        if (item.depth + 1 > kMaxBvhDepth) {
          return invalid_argument("wide bvh: deeper than " + std::to_string(kMaxBvhDepth) + " at node " +
                                  std::to_string(node.child[k]));
        }
        stack[size++] = {node.child[k], item.depth + 1};
      }
    }
  }
  return Status::Ok();
}

}  // namespace outcore
