// QuadtreeBrickAccel / QuadtreeBrickBuilder: a brick's triangles in a
// quadtree over its two dominant axes (quadtree_builder.h) traced front to
// back in the plane with each cell's height as a bound and a per-ray
// mailbox (quadtree_traversal.h), registered as "quadtree" in
// brick_accel_factory.cpp. The brick class is the split-plane trees'
// (kdtree/split_tree_brick.h: the hit contract, memory and thread-safety are
// stated there); QuadtreeBrickSerializer (quadtree_brick_serializer.h) keeps
// its bricks in the subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/kdtree/split_tree_brick.h"
#include "core/accel/quadtree/quadtree.h"
#include "core/accel/quadtree/quadtree_builder.h"

namespace outcore {

using QuadtreeBrickConfig = SplitTreeBrickConfig<QuadtreeBuilder::Config>;

struct QuadtreeBrickTraits {
  static constexpr const char* kName = "quadtree";
  using Builder = QuadtreeBuilder;
  using Tree = Quadtree;
  static std::unique_ptr<const BrickSerializer> make_serializer(const QuadtreeBrickConfig& config);
  // quadtree_traversal.h's walks (defined in quadtree_brick.cpp).
  template <class Test>
  static bool closest_hit(const QuadtreeView& tree, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const QuadtreeView& tree, const Ray& ray);
};

using QuadtreeBrickAccel = SplitTreeBrickAccel<QuadtreeBrickTraits>;
using QuadtreeBrickBuilder = SplitTreeBrickBuilder<QuadtreeBrickTraits>;
extern template class SplitTreeBrickAccel<QuadtreeBrickTraits>;

}  // namespace outcore
