// GridBrickAccel / GridBrickBuilder: a brick's triangles in a uniform grid
// (uniform_grid_builder.h) traced by the mailboxed 3D-DDA
// (uniform_grid_traversal.h), registered as "grid" in
// brick_accel_factory.cpp. The brick class is the one the split-plane trees
// use (split_tree_brick.h: the hit contract, memory and thread-safety are
// stated there), with the grid as its structure; GridBrickSerializer
// (grid_brick_serializer.h) keeps its bricks in the subtree tier.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <memory>

#include "core/accel/grid/uniform_grid.h"
#include "core/accel/grid/uniform_grid_builder.h"
#include "core/accel/kdtree/split_tree_brick.h"

namespace outcore {

using GridBrickConfig = SplitTreeBrickConfig<UniformGridBuilder::Config>;

struct GridBrickTraits {
  static constexpr const char* kName = "grid";
  using Builder = UniformGridBuilder;
  using Tree = UniformGrid;
  static std::unique_ptr<const BrickSerializer> make_serializer(const GridBrickConfig& config);
  // uniform_grid_traversal.h's walks (defined in grid_brick.cpp).
  template <class Test>
  static bool closest_hit(const UniformGridView& grid, const Ray& ray, Hit& best);
  template <class Test>
  static bool any_hit(const UniformGridView& grid, const Ray& ray);
};

using GridBrickAccel = SplitTreeBrickAccel<GridBrickTraits>;
using GridBrickBuilder = SplitTreeBrickBuilder<GridBrickTraits>;
extern template class SplitTreeBrickAccel<GridBrickTraits>;

}  // namespace outcore
