// Quadtree: a brick's triangles in a quadtree over its two dominant axes,
// for flat (2.5D) bricks such as terrain and city blocks. Each inner node is
// cut at the middle of its box along the plane's two axes (u, v) into four
// children stored consecutively (child k = first_child + k; bit 0 of k set
// for the upper half along u, bit 1 along v); the third axis (w, the
// brick's thinnest) is never cut. Instead every node carries the extent
// along w of the triangles filed under it, so a cell is a column clipped to
// the height its triangles reach: a ray over a terrain leaves a cell as soon
// as it is above that height, without testing anything. Leaves are runs of
// triangle references (a triangle touching several cells is referenced by
// each), and per triangle what a hit reports besides t, u, v. It shares the
// split-plane trees' layout and validate() (kdtree/split_tree.h) with
// 16-byte nodes.
//
// Neither the axes nor a node's box in the plane are stored: the axes follow
// from the tree's bounds (quadtree_axes), the boxes from the root's by
// halving with the one float expression the builder and the walk share
// (quadtree_child_box), so both see the same cells bit for bit.
//
// Built by QuadtreeBuilder (quadtree_builder.h), traversed by
// quadtree_traversal.h.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

#include "core/accel/kdtree/split_tree.h"
#include "core/geometry/aabb.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the traversal's fixed stack supports; the builder's depth
// limit never exceeds it.
inline constexpr uint32_t kMaxQuadtreeDepth = 24;

struct QuadtreeNode {
  // Inner: the first of the four children; leaf: the first reference.
  uint32_t word = 0;
  // Bit 0: leaf; above it the leaf's reference count.
  uint32_t bits = 1;
  // The extent along w of the triangles filed under this node (an empty
  // leaf's is unused).
  float w_lo = 0, w_hi = 0;

  static QuadtreeNode inner(uint32_t first_child, float w_lo, float w_hi) {
    return {first_child, 0, w_lo, w_hi};
  }
  static QuadtreeNode leaf(uint32_t first, uint32_t count, float w_lo, float w_hi) {
    return {first, (count << 1) | 1u, w_lo, w_hi};
  }

  bool is_leaf() const { return (bits & 1u) != 0; }
  bool is_empty() const { return bits == 1u; }
  uint32_t first_child() const { return word; }
  uint32_t first() const { return word; }
  uint32_t count() const { return bits >> 1; }

  // What SplitTreeView::validate() asks of a node type.
  static constexpr uint32_t kChildCount = 4;
  uint32_t child(uint32_t /*index*/, uint32_t k) const { return word + k; }
  static constexpr const char* kTreeName = "quadtree";
  static constexpr uint32_t kMaxDepth = kMaxQuadtreeDepth;
  Status check_inner(uint32_t /*index*/) const { return Status::Ok(); }
  Status check(uint32_t index) const {
    if (is_empty() || (std::isfinite(w_lo) && std::isfinite(w_hi) && w_lo <= w_hi)) return Status::Ok();
    return invalid_argument("quadtree: node " + std::to_string(index) +
                            "'s extent along its flat axis is not finite and ordered");
  }
};
static_assert(sizeof(QuadtreeNode) == 16);

// The most references a leaf can count (31 bits).
inline constexpr uint32_t kMaxQuadtreeLeafCount = (1u << 31) - 1;

using QuadtreeView = SplitTreeView<QuadtreeNode>;
using Quadtree = SplitTree<QuadtreeNode>;

// The plane's axes u < v and the flat axis w: w is the axis along which the
// bounds are thinnest (the last such at a tie, so a square terrain in x, y
// is cut in x, y).
struct QuadtreeAxes {
  int u, v, w;
};
inline QuadtreeAxes quadtree_axes(const Aabb& bounds) {
  const Vec3f extent = bounds.extent();
  int w = 2;
  for (int a = 1; a >= 0; --a) {
    if (extent[a] < extent[w]) w = a;
  }
  return {w == 0 ? 1 : 0, w == 2 ? 1 : 2, w};
}

// The middle of a box along u and v, and child k's box (bit 0 of k: the
// upper half along u, bit 1 along v; along w the parent's).
inline Aabb quadtree_child_box(const Aabb& box, const QuadtreeAxes& axes, float middle_u, float middle_v,
                               uint32_t k) {
  Aabb child = box;
  (k & 1u ? child.lo : child.hi)[axes.u] = middle_u;
  (k & 2u ? child.lo : child.hi)[axes.v] = middle_v;
  return child;
}
inline float quadtree_middle(const Aabb& box, int axis) {
  return box.lo[axis] + (box.hi[axis] - box.lo[axis]) * 0.5f;
}

}  // namespace outcore
