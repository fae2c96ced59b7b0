// QuadtreeBrickSerializer: the subtree tier's serialiser for "quadtree"
// bricks: the split-plane trees' payload (kdtree/split_tree_serializer.h:
// bounds, nodes, references, triangles, hit records) with 16-byte nodes
// (child or reference index, leaf bit and count, extent along the flat
// axis), the counts checked against the quadtree builder's budgets, under a
// structure key naming the payload version and every QuadtreeBrickConfig
// field.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/kdtree/split_tree_serializer.h"
#include "core/accel/quadtree/quadtree_brick.h"

namespace outcore {

struct QuadtreeSerializerTraits {
  using Accel = QuadtreeBrickAccel;
  using Tree = Quadtree;
  using Node = QuadtreeNode;
  static constexpr const char* kName = "quadtree";
  static constexpr uint64_t kMaxReferencesPerTriangle = QuadtreeBuilder::kMaxReferencesPerTriangle;
};

class QuadtreeBrickSerializer final : public SplitTreeSerializer<QuadtreeSerializerTraits> {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit QuadtreeBrickSerializer(const QuadtreeBrickConfig& config);
};

}  // namespace outcore
