// BinnedSahBuilder: top-down binned surface-area-heuristic builder (Wald 2007,
// "On fast construction of SAH-based bounding volume hierarchies") producing
// the nodes of a BvhTree over a span of triangles. It only decides the tree
// shape; the caller reorders its triangles by the returned order (leaves
// refer to positions in it). Deterministic: the same triangles and Config
// always give the same tree.
//
// Depth is bounded by kMaxBvhDepth: below depth kMaxBvhDepth - 33 every split
// is an object median, which halves the count, so at most 32 more levels.
//
// Thread-safety: build() is a pure function; call it from any thread.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

class BinnedSahBuilder {
 public:
  struct Config {
    // Candidate split planes per axis are the bin_count - 1 bin boundaries
    // over the node's centroid bounds. 16 is the usual choice (Wald 2007):
    // within a few percent of a full sweep for far less work. Range 2..256.
    uint32_t bin_count = 16;
    // A node with more triangles is always split (by object median if no bin
    // boundary separates them); at most this many may form a leaf when the
    // SAH says a leaf is cheaper, and a node of at most min(this, 8) is a
    // leaf without asking (the wide collapse keeps it one leaf anyway).
    // Range 1..255.
    uint32_t max_leaf_size = 8;
    // SAH cost of visiting an inner node (testing its two child boxes) and of
    // one triangle test, in the same unit. With a scalar two-box test and a
    // scalar triangle test they cost about the same, hence 1 and 1. Both > 0.
    float traversal_cost = 1.0f;
    float intersection_cost = 1.0f;

    // INVALID_ARGUMENT naming the field out of range.
    Status validate() const;
  };

  struct Result {
    std::vector<BvhNode> nodes;   // exact capacity
    std::vector<uint32_t> order;  // position j of the reordered triangles holds triangles[order[j]]
    uint64_t peak_bytes = 0;      // the builder's own peak allocation (not counting the input)
  };

  // triangles.size() < 2^32; config must be valid. Empty input gives no nodes.
  static Result build(std::span<const Triangle> triangles, const Config& config);

  // Upper bound on Result::peak_bytes for n triangles, whatever the config.
  static uint64_t peak_bytes_bound(uint64_t n);
};

}  // namespace outcore
