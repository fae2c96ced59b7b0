#include "core/accel/bsp/bsp_brick.h"

#include "core/accel/bsp/bsp_brick_serializer.h"
#include "core/accel/bsp/bsp_tree_traversal.h"
#include "core/accel/kdtree/split_tree_brick_impl.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> BspBrickTraits::make_serializer(const BspBrickConfig& config) {
  return std::make_unique<BspBrickSerializer>(config);
}

template <class Test>
bool BspBrickTraits::closest_hit(const BspTreeView& tree, const Ray& ray, Hit& best) {
  return bsp_closest_hit<Test>(tree, ray, best);
}

template <class Test>
bool BspBrickTraits::any_hit(const BspTreeView& tree, const Ray& ray) {
  return bsp_any_hit<Test>(tree, ray);
}

template class SplitTreeBrickAccel<BspBrickTraits>;

}  // namespace outcore
