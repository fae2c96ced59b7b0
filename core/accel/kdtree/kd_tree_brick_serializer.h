// KdTreeBrickSerializer: the subtree tier's serialiser for "kdtree" bricks,
// the split-plane trees' payload (split_tree_serializer.h) under a structure
// key that names the payload version and every KdTreeBrickConfig field, the
// costs as hexadecimal floats so that equal keys mean equal configs.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/kdtree/kd_tree_brick.h"
#include "core/accel/kdtree/split_tree_serializer.h"

namespace outcore {

struct KdTreeSerializerTraits {
  using Accel = KdTreeBrickAccel;
  using Tree = KdTree;
  using Node = KdNode;
  static constexpr const char* kName = "kdtree";
  static constexpr uint64_t kMaxReferencesPerTriangle = KdTreeBuilder::kMaxReferencesPerTriangle;
};

class KdTreeBrickSerializer final : public SplitTreeSerializer<KdTreeSerializerTraits> {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit KdTreeBrickSerializer(const KdTreeBrickConfig& config);
};

}  // namespace outcore
