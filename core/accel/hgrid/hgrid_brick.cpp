#include "core/accel/hgrid/hgrid_brick.h"

#include "core/accel/hgrid/hgrid_brick_serializer.h"
#include "core/accel/hgrid/hierarchical_grid_traversal.h"
#include "core/accel/kdtree/split_tree_brick_impl.h"

namespace outcore {

std::unique_ptr<const BrickSerializer> HgridBrickTraits::make_serializer(const HgridBrickConfig& config) {
  return std::make_unique<HgridBrickSerializer>(config);
}

template <class Test>
bool HgridBrickTraits::closest_hit(const HierarchicalGridView& grid, const Ray& ray, Hit& best) {
  return hgrid_closest_hit<Test>(grid, ray, best);
}

template <class Test>
bool HgridBrickTraits::any_hit(const HierarchicalGridView& grid, const Ray& ray) {
  return hgrid_any_hit<Test>(grid, ray);
}

template class SplitTreeBrickAccel<HgridBrickTraits>;

}  // namespace outcore
