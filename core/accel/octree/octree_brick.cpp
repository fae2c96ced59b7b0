#include "core/accel/octree/octree_brick.h"

#include "core/accel/kdtree/split_tree_brick_impl.h"
#include "core/accel/octree/octree_brick_serializer.h"
#include "core/accel/octree/octree_traversal.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> OctreeBrickTraits::make_serializer(const OctreeBrickConfig& config) {
  return std::make_unique<OctreeBrickSerializer>(config);
}

template <class Test>
bool OctreeBrickTraits::closest_hit(const OctreeView& tree, const Ray& ray, Hit& best) {
  return octree_closest_hit<Test>(tree, ray, best);
}

template <class Test>
bool OctreeBrickTraits::any_hit(const OctreeView& tree, const Ray& ray) {
  return octree_any_hit<Test>(tree, ray);
}

template class SplitTreeBrickAccel<OctreeBrickTraits>;

}  // namespace outcore
