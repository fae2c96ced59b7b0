// SplitTree<Node> / SplitTreeView<Node>: the layout the split-plane trees
// share (the kd-tree, kd_tree.h, the restricted BSP, bsp/bsp_tree.h, and
// the octree, octree/octree.h):
// the bounds of every triangle, nodes (8 bytes; the quadtree's 16) (nodes[0] the root; an inner
// node's child below its plane is the next node), leaves as runs of triangle
// references (a triangle crossing planes is referenced by every leaf it
// reaches), and per triangle what a hit reports besides t, u, v. The tree
// owns its arrays (a build); the view is what traversal reads.
//
// validate() checks a view's structure so that a view from elsewhere (a
// subtree file) is an error, never a crash: records match triangles,
// references within the triangles, every node reached once from the root
// (a node with two parents would make a walk exponential), depth within
// Node::kMaxDepth, children after their parent and in range, leaf runs
// within the references, and what the node type checks of its own
// (Node::check_inner: the split finite, the axis or direction known).
//
// Node provides: is_leaf(), first(), count(), kChildCount and
// child(index, k) (an inner node's children, each after it), kMaxDepth,
// kTreeName, and Status check_inner(uint32_t index) const (inner nodes), and
// optionally Status check(uint32_t index) const (every node). The octree
// (octree/octree.h) shares the layout with eight children a node, the
// quadtree (quadtree/quadtree.h) with four and 16-byte nodes.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/triangle_hit_records.h"
#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

template <class Node>
struct SplitTreeView {
  Aabb bounds;                     // of every triangle; traversal clips rays to it
  std::span<const Node> nodes;     // nodes[0] is the root; empty for a tree without triangles
  std::span<const uint32_t> refs;  // leaves' runs of triangle indices
  std::span<const Triangle> triangles;
  std::span<const BvhHitRecord> records;  // records[k] belongs to triangles[k]

  Status validate() const;
};

template <class Node>
struct SplitTree {
  Aabb bounds;
  std::vector<Node> nodes;
  std::vector<uint32_t> refs;
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;

  SplitTreeView<Node> view() const { return {bounds, nodes, refs, triangles, records}; }
  // A builder's first step: keeps the brick's triangles (in input order)
  // and their hit records (ids[k] belongs to triangles[k]).
  void adopt_triangles(std::vector<Triangle> input, std::span<const TriangleId> ids) {
    records = hit_records_for(input, ids);
    triangles = std::move(input);
  }
  // A builder's last: exact capacities, so memory_bytes() equals a
  // reloaded tree's (the subtree tier's accounting does not depend on
  // where a brick came from).
  void trim() {
    nodes.shrink_to_fit();
    refs.shrink_to_fit();
    triangles.shrink_to_fit();
  }
  uint64_t memory_bytes() const {
    return nodes.capacity() * sizeof(Node) + refs.capacity() * sizeof(uint32_t) +
           triangles.capacity() * sizeof(Triangle) + records.capacity() * sizeof(BvhHitRecord);
  }
};

template <class Node>
Status SplitTreeView<Node>::validate() const {
  const std::string name = Node::kTreeName;
  OUTCORE_RETURN_IF_ERROR(validate_triangle_refs(name, refs, triangles, records));
  if (nodes.empty()) return Status::Ok();
  // Depth-first from the root; (node, depth) pending.
  std::vector<uint8_t> seen(nodes.size(), 0);
  std::vector<std::pair<uint32_t, uint32_t>> pending{{0u, 1u}};
  while (!pending.empty()) {
    const auto [index, depth] = pending.back();
    pending.pop_back();
    if (seen[index]++ != 0)
      return invalid_argument(name + ": node " + std::to_string(index) + " has two parents");
    if (depth > Node::kMaxDepth) {
      return invalid_argument(name + ": deeper than " + std::to_string(Node::kMaxDepth) + " at node " +
                              std::to_string(index));
    }
    const Node& node = nodes[index];
    if constexpr (requires { node.check(index); }) OUTCORE_RETURN_IF_ERROR(node.check(index));
    if (node.is_leaf()) {
      if (uint64_t{node.first()} + node.count() > refs.size()) {
        return invalid_argument(name + ": leaf " + std::to_string(index) + " reaches past the " +
                                std::to_string(refs.size()) + " references");
      }
      continue;
    }
    OUTCORE_RETURN_IF_ERROR(node.check_inner(index));
    for (uint32_t k = 0; k < Node::kChildCount; ++k) {
      const uint32_t child = node.child(index, k);
      if (child <= index || child >= nodes.size()) {
        return invalid_argument(name + ": node " + std::to_string(index) + " has child " +
                                std::to_string(child) + " of " + std::to_string(nodes.size()));
      }
      pending.emplace_back(child, depth + 1);
    }
  }
  return Status::Ok();
}

}  // namespace outcore
