// OctreeBrickSerializer: the subtree tier's serialiser for "octree" bricks:
// the split-plane trees' payload (kdtree/split_tree_serializer.h: bounds,
// 8-byte nodes, references, triangles, hit records), the counts checked
// against the octree builder's budgets, under a structure key naming the
// payload version and every OctreeBrickConfig field.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/kdtree/split_tree_serializer.h"
#include "core/accel/octree/octree_brick.h"

namespace outcore {

struct OctreeSerializerTraits {
  using Accel = OctreeBrickAccel;
  using Tree = Octree;
  using Node = OctreeNode;
  static constexpr const char* kName = "octree";
  static constexpr uint64_t kMaxReferencesPerTriangle = OctreeBuilder::kMaxReferencesPerTriangle;
};

class OctreeBrickSerializer final : public SplitTreeSerializer<OctreeSerializerTraits> {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit OctreeBrickSerializer(const OctreeBrickConfig& config);
};

}  // namespace outcore
