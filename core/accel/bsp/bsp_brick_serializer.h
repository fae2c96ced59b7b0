// BspBrickSerializer: the subtree tier's serialiser for "bsp" bricks, the
// split-plane trees' payload (core/accel/kdtree/split_tree_serializer.h;
// a BSP node's direction index travels in its bits) under a structure key
// that names the payload version and every BspBrickConfig field (the
// directions included), the costs as hexadecimal floats.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/bsp/bsp_brick.h"
#include "core/accel/kdtree/split_tree_serializer.h"

namespace outcore {

struct BspSerializerTraits {
  using Accel = BspBrickAccel;
  using Tree = BspTree;
  using Node = BspNode;
  static constexpr const char* kName = "bsp";
  static constexpr uint64_t kMaxReferencesPerTriangle = BspTreeBuilder::kMaxReferencesPerTriangle;
};

class BspBrickSerializer final : public SplitTreeSerializer<BspSerializerTraits> {
 public:
  static constexpr int kPayloadVersion = 1;

  explicit BspBrickSerializer(const BspBrickConfig& config);
};

}  // namespace outcore
