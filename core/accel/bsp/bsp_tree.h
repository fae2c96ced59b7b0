// BspTree: a brick's restricted BSP tree in compact form, the kd-tree's
// layout (kd_tree.h) with planes of any of the 13 orientations of
// bsp_directions.h — 8-byte nodes (the split position n . p = s and, packed
// in one word, the direction index and the index of the child above the
// plane; the child below is the next node), leaves as runs of triangle
// references, and per triangle what a hit reports besides t, u, v. Built by
// BspTreeBuilder (bsp_tree_builder.h), traversed by bsp_tree_traversal.h.
//
// BspTree owns its arrays; BspTreeView is what traversal reads; both are the
// split-plane trees' shared layout (core/accel/kdtree/split_tree.h), whose
// validate() also asks a BspNode that its direction is known and its split
// finite.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/accel/bsp/bsp_directions.h"
#include "core/accel/kdtree/split_tree.h"
#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the traversal's fixed stack supports.
inline constexpr uint32_t kMaxBspDepth = 64;

struct BspNode {
  static constexpr uint32_t kLeaf = 15;

  // Inner: the split position's bits; leaf: the first reference.
  uint32_t word = 0;
  // Low four bits: the direction index (0..12), or kLeaf; above them the
  // index of the child above the plane (inner) or the leaf's reference count.
  uint32_t bits = kLeaf;

  static BspNode inner(uint32_t direction, float split, uint32_t above_child) {
    return {std::bit_cast<uint32_t>(split), (above_child << 4) | direction};
  }
  static BspNode leaf(uint32_t first, uint32_t count) { return {first, (count << 4) | kLeaf}; }

  bool is_leaf() const { return (bits & 15u) == kLeaf; }
  uint32_t direction() const { return bits & 15u; }
  float split() const { return std::bit_cast<float>(word); }
  uint32_t above_child() const { return bits >> 4; }
  uint32_t first() const { return word; }
  uint32_t count() const { return bits >> 4; }

  // What SplitTreeView::validate() asks of a node type.
  static constexpr uint32_t kChildCount = 2;
  uint32_t child(uint32_t index, uint32_t k) const { return k == 0 ? index + 1 : above_child(); }
  static constexpr const char* kTreeName = "bsp tree";
  static constexpr uint32_t kMaxDepth = kMaxBspDepth;
  Status check_inner(uint32_t index) const {
    if (direction() >= kBspDirectionCount) {
      return invalid_argument("bsp tree: node " + std::to_string(index) + " has direction " +
                              std::to_string(direction()) + " of " + std::to_string(kBspDirectionCount));
    }
    if (!std::isfinite(split())) {
      return invalid_argument("bsp tree: node " + std::to_string(index) + " splits at " +
                              std::to_string(split()));
    }
    return Status::Ok();
  }
};
static_assert(sizeof(BspNode) == 8);

// The most children indices and reference counts a node can hold (28 bits).
inline constexpr uint32_t kMaxBspIndex = (1u << 28) - 1;

using BspTreeView = SplitTreeView<BspNode>;
using BspTree = SplitTree<BspNode>;

}  // namespace outcore
