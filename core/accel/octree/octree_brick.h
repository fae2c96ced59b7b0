// OctreeBrickAccel / OctreeBrickBuilder: a brick's triangles in an octree
// (octree_builder.h) traced by the parametric walk with a per-ray mailbox
// (octree_traversal.h), registered as "octree" in brick_accel_factory.cpp.
// The brick class is the split-plane trees' (kdtree/split_tree_brick.h: the
// hit contract, memory and thread-safety are stated there);
// OctreeBrickSerializer (octree_brick_serializer.h) keeps its bricks in the
// subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/kdtree/split_tree_brick.h"
#include "core/accel/octree/octree.h"
#include "core/accel/octree/octree_builder.h"

namespace outcore {

using OctreeBrickConfig = SplitTreeBrickConfig<OctreeBuilder::Config>;

struct OctreeBrickTraits {
  static constexpr const char* kName = "octree";
  using Builder = OctreeBuilder;
  using Tree = Octree;
  static std::unique_ptr<const BrickSerializer> make_serializer(const OctreeBrickConfig& config);
  // octree_traversal.h's walks (defined in octree_brick.cpp).
  template <class Test>
  static bool closest_hit(const OctreeView& tree, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const OctreeView& tree, const Ray& ray);
};

using OctreeBrickAccel = SplitTreeBrickAccel<OctreeBrickTraits>;
using OctreeBrickBuilder = SplitTreeBrickBuilder<OctreeBrickTraits>;
extern template class SplitTreeBrickAccel<OctreeBrickTraits>;

}  // namespace outcore
