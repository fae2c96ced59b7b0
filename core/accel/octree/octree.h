// Octree: a brick's triangles in an octree over their bounds — each inner
// node cut at the middle of its box along all three axes into eight
// children stored consecutively (child k = first_child + k, bit a of k set
// for the upper half along axis a), leaves as runs of triangle references
// (a triangle touching several cells is referenced by each), and per
// triangle what a hit reports besides t, u, v. It shares the split-plane
// trees' layout and validate() (kdtree/split_tree.h) with 8-byte nodes.
//
// A node's box is not stored: it follows from the root's bounds by halving,
// with one float expression (octree_child_box) the builder and the walk
// share, so both see the same cells bit for bit.
//
// Built by OctreeBuilder (octree_builder.h), traversed by
// octree_traversal.h.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <cstdint>

#include "core/accel/kdtree/split_tree.h"
#include "core/geometry/aabb.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the traversal's fixed stack supports; the builder's depth
// limit never exceeds it.
inline constexpr uint32_t kMaxOctreeDepth = 24;

struct OctreeNode {
  // Inner: the first of the eight children; leaf: the first reference.
  uint32_t word = 0;
  // Bit 0: leaf; above it the leaf's reference count.
  uint32_t bits = 1;

  static OctreeNode inner(uint32_t first_child) { return {first_child, 0}; }
  static OctreeNode leaf(uint32_t first, uint32_t count) { return {first, (count << 1) | 1u}; }

  bool is_leaf() const { return (bits & 1u) != 0; }
  uint32_t first_child() const { return word; }
  uint32_t first() const { return word; }
  uint32_t count() const { return bits >> 1; }

  // What SplitTreeView::validate() asks of a node type.
  static constexpr uint32_t kChildCount = 8;
  uint32_t child(uint32_t /*index*/, uint32_t k) const { return word + k; }
  static constexpr const char* kTreeName = "octree";
  static constexpr uint32_t kMaxDepth = kMaxOctreeDepth;
  Status check_inner(uint32_t /*index*/) const { return Status::Ok(); }
};
static_assert(sizeof(OctreeNode) == 8);

// The most references a leaf can count (31 bits).
inline constexpr uint32_t kMaxOctreeLeafCount = (1u << 31) - 1;

using OctreeView = SplitTreeView<OctreeNode>;
using Octree = SplitTree<OctreeNode>;

// The middle of a box along each axis, and child k's box (bit a of k: the
// upper half along axis a).
inline Vec3f octree_middle(const Aabb& box) {
  return {box.lo.x + (box.hi.x - box.lo.x) * 0.5f, box.lo.y + (box.hi.y - box.lo.y) * 0.5f,
          box.lo.z + (box.hi.z - box.lo.z) * 0.5f};
}
inline Aabb octree_child_box(const Aabb& box, const Vec3f& middle, uint32_t k) {
  Aabb child;
  for (int a = 0; a < 3; ++a) {
    const bool upper = (k >> a) & 1u;
    child.lo[a] = upper ? middle[a] : box.lo[a];
    child.hi[a] = upper ? box.hi[a] : middle[a];
  }
  return child;
}

}  // namespace outcore
