#include "core/accel/quadtree/quadtree_brick.h"

#include "core/accel/kdtree/split_tree_brick_impl.h"
#include "core/accel/quadtree/quadtree_brick_serializer.h"
#include "core/accel/quadtree/quadtree_traversal.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> QuadtreeBrickTraits::make_serializer(
    const QuadtreeBrickConfig& config) {
  return std::make_unique<QuadtreeBrickSerializer>(config);
}

template <class Test>
bool QuadtreeBrickTraits::closest_hit(const QuadtreeView& tree, const Ray& ray, Hit& best) {
  return quadtree_closest_hit<Test>(tree, ray, best);
}

template <class Test>
bool QuadtreeBrickTraits::any_hit(const QuadtreeView& tree, const Ray& ray) {
  return quadtree_any_hit<Test>(tree, ray);
}

template class SplitTreeBrickAccel<QuadtreeBrickTraits>;

}  // namespace outcore
