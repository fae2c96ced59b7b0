// BvhBrickSet: the resident-set fast path (resident_brick_set.h) for bvh
// bricks, for any number of them. A ray walks a wide BVH over the bricks'
// trees (wide_bvh_top_level.h) and searches the bricks it enters nearest
// first with one set of per-ray constants, carrying its best hit from brick
// to brick — a two-level BVH, as one BVH over the whole scene would be; for a scene of one brick that is
// exactly the brick's own traversal, without the upper-hierarchy walk, the proxies or the per-brick queues.
// Nothing is copied: the set refers to the bricks' trees.
//
// Answers are bitwise those of tracing the bricks one by one: the same
// traversal and triangle test per brick, ties settled by hit_is_better()
// whichever brick they lie in.
//
// Lifetime: the bricks must outlive the set (the engine pins them).
//
// Thread-safety: a made set is immutable; intersect() and occluded() may run
// concurrently on disjoint ray subsets.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "core/accel/bvh/bvh_brick.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/accel/resident_brick_set.h"
#include "core/util/status.h"

namespace outcore {

class BvhBrickSet final : public ResidentBrickSet {
 public:
  // Over `bricks` (each non-null, all with the same triangle test; a brick
  // without triangles adds nothing). INVALID_ARGUMENT for mixed tests.
  static Expected<std::unique_ptr<BvhBrickSet>> build(std::span<const BvhBrickAccel* const> bricks);

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;

  uint32_t tree_count() const { return static_cast<uint32_t>(trees_.size()); }

 private:
  BvhBrickSet() = default;

  TriangleTest test_ = TriangleTest::kWatertight;
  std::vector<WideBvhView> trees_;
  std::vector<WideBvhNode> top_;
};

}  // namespace outcore
