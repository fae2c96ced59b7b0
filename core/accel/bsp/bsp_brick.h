// BspBrickAccel / BspBrickBuilder: a brick's triangles in an SAH restricted
// BSP tree (bsp_tree_builder.h: planes along 3, 7 or 13 fixed orientations)
// traced by the kd-tree's front-to-back stack walk (bsp_tree_traversal.h):
// the split-plane brick (core/accel/kdtree/split_tree_brick.h, which states
// the hit contract, memory and thread-safety) for the BSP, registered as
// "bsp" in brick_accel_factory.cpp; BspBrickSerializer
// (bsp_brick_serializer.h) keeps its bricks in the subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/bsp/bsp_tree.h"
#include "core/accel/bsp/bsp_tree_builder.h"
#include "core/accel/kdtree/split_tree_brick.h"

namespace outcore {

using BspBrickConfig = SplitTreeBrickConfig<BspTreeBuilder::Config>;

struct BspBrickTraits {
  static constexpr const char* kName = "bsp";
  using Builder = BspTreeBuilder;
  using Tree = BspTree;
  static std::unique_ptr<const BrickSerializer> make_serializer(const BspBrickConfig& config);
  // bsp_tree_traversal.h's walks (defined in bsp_brick.cpp).
  template <class Test>
  static bool closest_hit(const BspTreeView& tree, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const BspTreeView& tree, const Ray& ray);
};

using BspBrickAccel = SplitTreeBrickAccel<BspBrickTraits>;
using BspBrickBuilder = SplitTreeBrickBuilder<BspBrickTraits>;
extern template class SplitTreeBrickAccel<BspBrickTraits>;

}  // namespace outcore
