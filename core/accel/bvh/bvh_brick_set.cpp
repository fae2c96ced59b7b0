#include "core/accel/bvh/bvh_brick_set.h"

#include <string>
#include <vector>

#include "core/accel/bvh/wide_bvh_top_level.h"
#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore {
namespace {

// The union of a tree's root children's boxes: the tree's bounds.
Aabb tree_bounds(const WideBvhView& tree) {
  Aabb box;
  const WideBvhNode& root = tree.nodes[0];
  for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
    if (root.child_mask() >> k & 1) box.extend(root.box(k));
  }
  return box;
}

}  // namespace

Expected<std::unique_ptr<BvhBrickSet>> BvhBrickSet::build(std::span<const BvhBrickAccel* const> bricks) {
  std::unique_ptr<BvhBrickSet> set(new BvhBrickSet());
  bool first = true;
  for (const BvhBrickAccel* brick : bricks) {
    if (first) set->test_ = brick->triangle_test();
    first = false;
    if (brick->triangle_test() != set->test_) {
      return invalid_argument("bvh brick set: brick " + std::to_string(brick->brick_id()) +
                              " uses triangle test " +
                              std::string(triangle_test_name(brick->triangle_test())) + ", the set " +
                              std::string(triangle_test_name(set->test_)));
    }
    if (brick->view().nodes.empty()) continue;
    set->trees_.push_back(brick->view());
  }
  std::vector<Aabb> bounds(set->trees_.size());
  for (std::size_t t = 0; t < bounds.size(); ++t) bounds[t] = tree_bounds(set->trees_[t]);
  set->top_ = build_wide_top_level(bounds);
  return set;
}

void BvhBrickSet::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  wide_bvh_set_intersect(active_simd_path(), test_, {trees_, top_}, ray_ids, rays, hits);
}

void BvhBrickSet::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  wide_bvh_set_occluded(active_simd_path(), test_, {trees_, top_}, ray_ids, rays, occluded);
}

Expected<std::unique_ptr<ResidentBrickSet>> BvhBrickBuilder::make_resident_set(
    std::span<const BrickAccel* const> bricks) const {
  // Every brick of this builder is a BvhBrickAccel.
  std::vector<const BvhBrickAccel*> accels(bricks.size());
  for (std::size_t b = 0; b < bricks.size(); ++b) accels[b] = static_cast<const BvhBrickAccel*>(bricks[b]);
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<BvhBrickSet> set, BvhBrickSet::build(accels));
  return std::unique_ptr<ResidentBrickSet>(std::move(set));
}

}  // namespace outcore
