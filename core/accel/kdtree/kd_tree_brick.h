// KdTreeBrickAccel / KdTreeBrickBuilder: a brick's triangles in an SAH
// kd-tree (kd_tree_builder.h) traced by the front-to-back stack walk
// (kd_tree_traversal.h): the split-plane brick (split_tree_brick.h, which
// states the hit contract, memory and thread-safety) for the kd-tree,
// registered as "kdtree" in brick_accel_factory.cpp; KdTreeBrickSerializer
// (kd_tree_brick_serializer.h) keeps its bricks in the subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/kdtree/kd_tree.h"
#include "core/accel/kdtree/kd_tree_builder.h"
#include "core/accel/kdtree/split_tree_brick.h"

namespace outcore {

using KdTreeBrickConfig = SplitTreeBrickConfig<KdTreeBuilder::Config>;

struct KdTreeBrickTraits {
  static constexpr const char* kName = "kdtree";
  using Builder = KdTreeBuilder;
  using Tree = KdTree;
  static std::unique_ptr<const BrickSerializer> make_serializer(const KdTreeBrickConfig& config);
  // kd_tree_traversal.h's walks (defined in kd_tree_brick.cpp).
  template <class Test>
  static bool closest_hit(const KdTreeView& tree, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const KdTreeView& tree, const Ray& ray);
};

using KdTreeBrickAccel = SplitTreeBrickAccel<KdTreeBrickTraits>;
using KdTreeBrickBuilder = SplitTreeBrickBuilder<KdTreeBrickTraits>;
extern template class SplitTreeBrickAccel<KdTreeBrickTraits>;

}  // namespace outcore
