// BvhTree: a brick's bounding volume hierarchy in compact form — 32-byte
// nodes (box, then either the index of the first of two adjacent children or a
// range of triangles), the triangles reordered so that every leaf is one
// contiguous range, and per triangle what a hit reports besides t, u, v (the
// user's ids and the unit normal). Built by BinnedSahBuilder (binned_sah_builder.h),
// traversed by bvh_traversal.h; the tree itself knows neither.
//
// BvhTree owns its arrays (a build); BvhTreeView is what traversal reads: the
// same three arrays as spans, over a BvhTree or over a loaded subtree file,
// read in place (bvh_brick_serializer.h). validate() checks a view that came from a
// file before it is used, so a corrupt or hostile file is an error, never a
// crash.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the fixed traversal stack supports; the builder never exceeds
// it (it falls back to median splits well before) and validate() checks it.
inline constexpr uint32_t kMaxBvhDepth = 64;

struct BvhNode {
  Aabb bounds;
  uint32_t index = 0;  // inner: first child (the second is index + 1); leaf: first triangle
  uint32_t count = 0;  // 0 for an inner node, else the leaf's triangle count

  bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32);

// What a hit on triangle k reports besides t, u, v.
struct BvhHitRecord {
  Vec3f normal;  // unit, normalize(cross(v1 - v0, v2 - v0)) in float64, rounded
  uint32_t geometry_id;
  uint32_t primitive_id;
};
static_assert(sizeof(BvhHitRecord) == 20);

struct BvhTreeView {
  std::span<const BvhNode> nodes;  // nodes[0] is the root; empty for a tree without triangles
  std::span<const Triangle> triangles;
  std::span<const BvhHitRecord> records;  // records[k] belongs to triangles[k]

  // Structural checks: children after their parent and in range, leaves
  // covering the triangles in range, depth <= kMaxBvhDepth, one record per
  // triangle. Boxes are not checked against their contents (that would cost
  // as much as a build); a wrong box can only lose hits, never crash.
  Status validate() const;
};

struct BvhTree {
  std::vector<BvhNode> nodes;
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;

  BvhTreeView view() const { return {nodes, triangles, records}; }
  static BvhTree copy_of(const BvhTreeView& view) {
    return {{view.nodes.begin(), view.nodes.end()},
            {view.triangles.begin(), view.triangles.end()},
            {view.records.begin(), view.records.end()}};
  }
  uint64_t memory_bytes() const {
    return nodes.capacity() * sizeof(BvhNode) + triangles.capacity() * sizeof(Triangle) +
           records.capacity() * sizeof(BvhHitRecord);
  }
};

}  // namespace outcore
