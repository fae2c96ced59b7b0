#include "core/accel/kdtree/kd_tree_brick.h"

#include "core/accel/kdtree/kd_tree_brick_serializer.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/accel/kdtree/split_tree_brick_impl.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> KdTreeBrickTraits::make_serializer(const KdTreeBrickConfig& config) {
  return std::make_unique<KdTreeBrickSerializer>(config);
}

template <class Test>
bool KdTreeBrickTraits::closest_hit(const KdTreeView& tree, const Ray& ray, Hit& best) {
  return kd_closest_hit<Test>(tree, ray, best);
}

template <class Test>
bool KdTreeBrickTraits::any_hit(const KdTreeView& tree, const Ray& ray) {
  return kd_any_hit<Test>(tree, ray);
}

template class SplitTreeBrickAccel<KdTreeBrickTraits>;

}  // namespace outcore
