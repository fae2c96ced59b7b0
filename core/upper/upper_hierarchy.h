// UpperHierarchy: the fixed binary BVH over brick bounds that the server keeps
// resident. It is built once at pack time (upper_hierarchy_builder.h), stored in
// the manifest, and never changes; its leaves are exactly the bricks, one each.
// Node layout: children of an inner node are stored next to each other, so an
// inner node keeps only the index of its first child.
//
// Thread-safety: immutable after construction; safe to read from any thread.
#pragma once

#include <cstdint>
#include <vector>

#include "core/geometry/aabb.h"

namespace outcore {

struct UpperNode {
  Aabb bounds;
  // Inner node: index of the left child (right child = left + 1).
  // Leaf: the brick id.
  uint32_t child_or_brick = 0;
  uint32_t is_leaf = 0;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(bounds.lo.x, bounds.lo.y, bounds.lo.z, bounds.hi.x, bounds.hi.y, bounds.hi.z, child_or_brick, is_leaf);
  }
  bool operator==(const UpperNode&) const = default;
};

struct UpperHierarchy {
  std::vector<UpperNode> nodes;  // nodes[0] is the root (a leaf when there is one brick)

  bool empty() const { return nodes.empty(); }
  // Longest root-to-leaf path, counting nodes (a single leaf has depth 1).
  uint32_t depth() const;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(nodes);
  }
};

}  // namespace outcore
