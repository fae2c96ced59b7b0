// WideBvhCollapser: turns a binary SAH tree (BinnedSahBuilder's nodes and
// order) into a WideBvh (wide_bvh.h): each wide node takes the binary
// subtree's nodes top-down, always opening the child of largest surface area,
// until it has 8 children or only leaves are left (Wald et al. 2008, "Getting
// rid of packets"; the usual BVH8 collapse). A binary subtree of at most one
// packet's worth of triangles (8) becomes a single leaf, and sibling leaves are
// merged into one packet when the merged box has no more area than the two
// boxes together (the SAH with a packet test as the unit of cost), so the
// leaves fill packets and a leaf costs one SIMD test.
//
// Slots are laid out depth first. A leaf that would straddle two packets, and
// fit in fewer if it started at a packet boundary, is moved to the next
// boundary while the padding so far stays within a quarter of the triangle
// count, so slots <= 1.25 n + 8 whatever the tree.
//
// Deterministic: the same input gives the same WideBvh.
//
// Thread-safety: collapse() is a pure function; call it from any thread.
#pragma once

#include <cstdint>
#include <span>

#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"

namespace outcore {

class WideBvhCollapser {
 public:
  struct Result {
    WideBvh tree;             // exact capacity
    uint64_t peak_bytes = 0;  // the collapser's own peak allocation, the result included
  };

  // nodes: a valid binary tree over triangles (BvhTreeView::validate), whose
  // leaf positions j refer to triangles[order[j]] and ids[order[j]].
  static Result collapse(std::span<const BvhNode> nodes, std::span<const uint32_t> order,
                         std::span<const Triangle> triangles, std::span<const TriangleId> ids);

  // Upper bound on Result::peak_bytes for n triangles.
  static uint64_t peak_bytes_bound(uint64_t n);
};

}  // namespace outcore
