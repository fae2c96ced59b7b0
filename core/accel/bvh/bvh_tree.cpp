#include "core/accel/bvh/bvh_tree.h"

#include <string>

namespace outcore {

Status BvhTreeView::validate() const {
  if (records.size() != triangles.size()) {
    return invalid_argument("bvh: " + std::to_string(triangles.size()) + " triangles but " +
                            std::to_string(records.size()) + " hit records");
  }
  if (nodes.empty()) {
    if (!triangles.empty()) return invalid_argument("bvh: triangles but no nodes");
    return Status::Ok();
  }
  // Depth by a walk from the root; children strictly after their parent, so
  // there are no cycles and the walk ends. A depth-first walk holds at most
  // one pending sibling per level, so a fixed stack suffices once the depth
  // is bounded.
  struct Item {
    uint32_t node, depth;
  };
  Item stack[kMaxBvhDepth + 2];
  std::size_t size = 0;
  stack[size++] = {0, 1};
  uint64_t covered = 0;
  while (size > 0) {
    const Item item = stack[--size];
    const BvhNode& node = nodes[item.node];
    if (node.is_leaf()) {
      if (uint64_t{node.index} + node.count > triangles.size()) {
        return invalid_argument("bvh: leaf " + std::to_string(item.node) + " reaches past the triangles");
      }
      covered += node.count;
      if (covered > triangles.size()) return invalid_argument("bvh: leaves overlap");
      continue;
    }
    if (node.index <= item.node || uint64_t{node.index} + 1 >= nodes.size()) {
      return invalid_argument("bvh: node " + std::to_string(item.node) + " has children out of range");
    }
    if (item.depth + 1 > kMaxBvhDepth) {
      return invalid_argument("bvh: deeper than " + std::to_string(kMaxBvhDepth) + " at node " +
                              std::to_string(node.index));
    }
    stack[size++] = {node.index, item.depth + 1};
    stack[size++] = {node.index + 1, item.depth + 1};
  }
  return Status::Ok();
}

}  // namespace outcore
