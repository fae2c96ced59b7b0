// KdTree: a brick's SAH kd-tree in compact form — 8-byte nodes (the split
// position and, packed in one word, the axis and the index of the child
// above the split; the child below is the next node), leaves as runs of
// triangle references (a triangle that crosses split planes is referenced by
// every leaf it reaches), and per triangle what a hit reports besides t, u, v.
// Built by KdTreeBuilder (kd_tree_builder.h), traversed by
// kd_tree_traversal.h; the tree itself knows neither.
//
// KdTree owns its arrays (a build); KdTreeView is what traversal reads; both
// are the split-plane trees' shared layout (split_tree.h), whose validate()
// also asks a KdNode that its split is not NaN.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <bit>
#include <cstdint>
#include <string>

#include "core/accel/kdtree/split_tree.h"
#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the traversal's fixed stack supports; the builder's depth limit
// never exceeds it.
inline constexpr uint32_t kMaxKdDepth = 64;

struct KdNode {
  static constexpr uint32_t kLeaf = 3;

  // Inner: the split position's bits; leaf: the first reference.
  uint32_t word = 0;
  // Low two bits: the split axis (0..2), or kLeaf; above them the index of
  // the child above the split (inner) or the leaf's reference count.
  uint32_t bits = kLeaf;

  static KdNode inner(int axis, float split, uint32_t above_child) {
    return {std::bit_cast<uint32_t>(split), (above_child << 2) | static_cast<uint32_t>(axis)};
  }
  static KdNode leaf(uint32_t first, uint32_t count) { return {first, (count << 2) | kLeaf}; }

  bool is_leaf() const { return (bits & 3u) == kLeaf; }
  int axis() const { return static_cast<int>(bits & 3u); }
  float split() const { return std::bit_cast<float>(word); }
  uint32_t above_child() const { return bits >> 2; }
  uint32_t first() const { return word; }
  uint32_t count() const { return bits >> 2; }

  // What SplitTreeView::validate() asks of a node type.
  static constexpr uint32_t kChildCount = 2;
  uint32_t child(uint32_t index, uint32_t k) const { return k == 0 ? index + 1 : above_child(); }
  static constexpr const char* kTreeName = "kd-tree";
  static constexpr uint32_t kMaxDepth = kMaxKdDepth;
  Status check_inner(uint32_t index) const {
    if (split() != split())
      return invalid_argument("kd-tree: node " + std::to_string(index) + " splits at NaN");
    return Status::Ok();
  }
};
static_assert(sizeof(KdNode) == 8);

// The most children indices and reference counts a node can hold (30 bits).
inline constexpr uint32_t kMaxKdIndex = (1u << 30) - 1;

using KdTreeView = SplitTreeView<KdNode>;
using KdTree = SplitTree<KdNode>;

}  // namespace outcore
