// HgridBrickAccel / HgridBrickBuilder: a brick's triangles in a two-level
// grid (hierarchical_grid_builder.h) traced by the nested conservative
// 3D-DDA with a per-ray mailbox (hierarchical_grid_traversal.h), registered
// as "hgrid" in brick_accel_factory.cpp. The brick class is the one the
// split-plane trees use (kdtree/split_tree_brick.h: the hit contract, memory
// and thread-safety are stated there), with the grid as its structure;
// HgridBrickSerializer (hgrid_brick_serializer.h) keeps its bricks in the
// subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/hgrid/hierarchical_grid.h"
#include "core/accel/hgrid/hierarchical_grid_builder.h"
#include "core/accel/kdtree/split_tree_brick.h"

namespace outcore {

using HgridBrickConfig = SplitTreeBrickConfig<HierarchicalGridBuilder::Config>;

struct HgridBrickTraits {
  static constexpr const char* kName = "hgrid";
  using Builder = HierarchicalGridBuilder;
  using Tree = HierarchicalGrid;
  static std::unique_ptr<const BrickSerializer> make_serializer(const HgridBrickConfig& config);
  // hierarchical_grid_traversal.h's walks (defined in hgrid_brick.cpp).
  template <class Test>
  static bool closest_hit(const HierarchicalGridView& grid, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const HierarchicalGridView& grid, const Ray& ray);
};

using HgridBrickAccel = SplitTreeBrickAccel<HgridBrickTraits>;
using HgridBrickBuilder = SplitTreeBrickBuilder<HgridBrickTraits>;
extern template class SplitTreeBrickAccel<HgridBrickTraits>;

}  // namespace outcore
