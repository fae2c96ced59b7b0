// EmbreeBrickSet: one Embree scene that instances the scenes of a set of
// built Embree bricks (identity transforms), so that a ray crosses all of
// them in one rtcIntersect1 / rtcOccluded1 call. For a batch over a scene
// whose bricks are all resident it replaces the upper-hierarchy walk, the
// rounds of per-brick tracing and one Embree call per brick visit by
// Embree's own two-level traversal (its top-level BVH over the bricks'
// boxes); nothing is loaded, built or copied, the set only refers to the
// bricks' scenes. When only one brick has triangles, the set is that brick's
// own scene (no level of instancing: a scene packed as one brick is traced as
// one Embree scene).
//
// Answers are bitwise those of tracing the bricks one by one in front-to-back
// order: the triangle tests are the bricks' own on the same ray values (an
// identity transform changes no finite non-zero value; origins and
// directions reach Embree with negative zeros as +0 on every path, so it
// changes nothing at all), and the tie filter settles every candidate by
// hit_is_better(), whichever brick it lies in, as it does between bricks
// (docs/DESIGN.md, "Resident scenes in one Embree call").
//
// Lifetime: the set's scene holds references to the bricks' scenes, and the
// tie filter reads the bricks' hit records, so the bricks must outlive the
// set (the engine keeps them pinned while a set exists).
//
// Thread-safety: build() may run concurrently with brick builds (it runs in
// an EmbreeDevice section); a built set is immutable and intersect() /
// occluded() may run concurrently on disjoint ray subsets.
#pragma once

#include <embree3/rtcore.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/accel/embree_brick.h"
#include "core/accel/resident_brick_set.h"
#include "core/util/status.h"

namespace outcore {

class EmbreeBrickSet final : public ResidentBrickSet {
 public:
  // Over `bricks` (each non-null, in any order; a brick without triangles
  // adds nothing). Embree's errors as Status.
  static Expected<std::unique_ptr<EmbreeBrickSet>> build(std::span<const EmbreeBrickAccel* const> bricks);
  ~EmbreeBrickSet() override;
  EmbreeBrickSet(const EmbreeBrickSet&) = delete;
  EmbreeBrickSet& operator=(const EmbreeBrickSet&) = delete;

  // As BrickAccel::intersect / occluded, over every brick of the set.
  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;

  // The bricks it was built over, in the order given.
  const std::vector<const EmbreeBrickAccel*>& bricks() const { return bricks_; }
  // What Embree's memory monitor attributed to the set's own scene (its
  // top-level BVH), plus the untracked objects (an instance per brick); 0
  // when only one brick has triangles (its own scene is used).
  uint64_t memory_bytes() const { return memory_bytes_; }
  // Rays (closest and any hit) that went to Embree in coherent streams.
  uint64_t coherent_rays() const { return coherent_rays_.load(std::memory_order_relaxed); }

 private:
  EmbreeBrickSet() = default;
  EmbreeBrickAccel::TraceTarget target() const;

  RTCScene scene_ = nullptr;  // null when no brick has triangles
  bool owns_scene_ = true;    // false: the scene of the only brick with triangles
  std::vector<const EmbreeBrickAccel*> bricks_;
  float max_extent_ = 0;
  Vec3f center_;
  uint64_t memory_bytes_ = 0;
  mutable std::atomic<uint64_t> coherent_rays_{0};
};

}  // namespace outcore
