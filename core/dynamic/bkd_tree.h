// BkdTree: the bounding kd-tree of the seed (Woop, Marmitt & Slusallek 2006,
// "B-KD Trees for Hardware Accelerated Ray Tracing of Dynamic Scenes") over
// the dynamic layer's instances: a binary tree built like a kd-tree (each
// inner node cuts its instances at the median of their box centres along
// the axis where those centres spread most), where each of the two children
// is bounded by two planes along the node's axis only — the interval its
// instances' boxes cover there. Moving instances keeps the tree's shape and
// refits the intervals bottom-up; a ray clips its interval against one slab
// per node instead of a box, so a node costs less to visit and culls less
// than a BVH node; leaves test the instance's own box.
//
// The alternative to the 8-wide BVH top level (DynamicTopLevel::kBvh, the
// default), compared in docs/BENCHMARKS.md.
//
// Thread-safety: immutable after build/refit; walks from any thread.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry/aabb.h"

namespace outcore {

struct BkdNode {
  float lo[2], hi[2];  // child c's interval along `axis`
  uint32_t child[2];   // inner: node index (after this one); leaf: instance index
  uint8_t axis = 0;
  uint8_t leaf_mask = 0;  // bit c: child c is an instance
};

class BkdTree {
 public:
  // Over the non-empty boxes; no boxes, no nodes. One box: a root with one
  // real child (both children name it).
  static BkdTree build(std::span<const Aabb> boxes);
  // The intervals recomputed from the boxes (same instances, same order).
  void refit(std::span<const Aabb> boxes);
  // Expected node visits and leaf tests for a ray through the root's box,
  // weighted by interval-slab areas: comparable across refits of one tree.
  double cost(std::span<const Aabb> boxes) const;

  const std::vector<BkdNode>& nodes() const { return nodes_; }
  // The union of the boxes: a ray's interval is clipped to it first, since
  // an axis no node splits along would otherwise never bound it.
  const Aabb& bounds() const { return bounds_; }
  bool empty() const { return nodes_.empty(); }

  // Enough for any tree build() makes (median splits: depth <= log2 n + 1).
  static constexpr std::size_t kMaxDepth = 64;

 private:
  uint32_t make(std::span<uint32_t> items, std::span<const Aabb> boxes);
  std::vector<BkdNode> nodes_;
  Aabb bounds_;
};

}  // namespace outcore
