// BspTree: a brick's restricted BSP tree in compact form, the kd-tree's
// layout (kd_tree.h) with planes of any of the 13 orientations of
// bsp_directions.h — 8-byte nodes (the split position n . p = s and, packed
// in one word, the direction index and the index of the child above the
// plane; the child below is the next node), leaves as runs of triangle
// references, and per triangle what a hit reports besides t, u, v. Built by
// BspTreeBuilder (bsp_tree_builder.h), traversed by bsp_tree_traversal.h.
//
// BspTree owns its arrays; BspTreeView is what traversal reads. validate()
// checks a view's structure (children after their parent and in range,
// direction indices known, leaf runs within the references, references
// within the triangles, depth within kMaxBspDepth) so that a view from
// elsewhere is an error, never a crash.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <bit>
#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/bsp/bsp_directions.h"
#include "core/accel/bvh/bvh_tree.h"
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
};
static_assert(sizeof(BspNode) == 8);

// The most children indices and reference counts a node can hold (28 bits).
inline constexpr uint32_t kMaxBspIndex = (1u << 28) - 1;

struct BspTreeView {
  Aabb bounds;                     // of every triangle; traversal clips rays to it
  std::span<const BspNode> nodes;  // nodes[0] is the root; empty for a tree without triangles
  std::span<const uint32_t> refs;  // leaves' runs of triangle indices
  std::span<const Triangle> triangles;
  std::span<const BvhHitRecord> records;  // records[k] belongs to triangles[k]

  Status validate() const;
};

struct BspTree {
  Aabb bounds;
  std::vector<BspNode> nodes;
  std::vector<uint32_t> refs;
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;

  BspTreeView view() const { return {bounds, nodes, refs, triangles, records}; }
  uint64_t memory_bytes() const {
    return nodes.capacity() * sizeof(BspNode) + refs.capacity() * sizeof(uint32_t) +
           triangles.capacity() * sizeof(Triangle) + records.capacity() * sizeof(BvhHitRecord);
  }
};

}  // namespace outcore
