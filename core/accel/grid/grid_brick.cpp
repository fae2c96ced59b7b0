#include "core/accel/grid/grid_brick.h"

#include "core/accel/grid/grid_brick_serializer.h"
#include "core/accel/grid/uniform_grid_traversal.h"
#include "core/accel/kdtree/split_tree_brick_impl.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> GridBrickTraits::make_serializer(const GridBrickConfig& config) {
  return std::make_unique<GridBrickSerializer>(config);
}

template <class Test>
bool GridBrickTraits::closest_hit(const UniformGridView& grid, const Ray& ray, Hit& best) {
  return grid_closest_hit<Test>(grid, ray, best);
}

template <class Test>
bool GridBrickTraits::any_hit(const UniformGridView& grid, const Ray& ray) {
  return grid_any_hit<Test>(grid, ray);
}

template class SplitTreeBrickAccel<GridBrickTraits>;

}  // namespace outcore
