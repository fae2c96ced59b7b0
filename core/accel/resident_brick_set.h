// ResidentBrickSet: a fast path a brick structure may offer for batches over
// a scene whose bricks are all resident: one structure over every brick that
// a ray crosses in one call, in place of the upper-hierarchy walk and a call
// per brick visit. BrickBuilder::make_resident_set() makes one; structures
// without such a path return nullptr there and the engine walks the bricks.
//
// Answers must be bitwise those of tracing the bricks one by one front to
// back (ties settled by hit_is_better(), whichever brick they lie in).
//
// Lifetime: a set refers to the bricks it was made over; they must stay
// pinned while it exists.
//
// Thread-safety: a made set is immutable; intersect() and occluded() may run
// concurrently on disjoint ray subsets.
#pragma once

#include <cstdint>
#include <span>

#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

namespace outcore {

// The most bricks a set is offered for by the structures that have one
// (BrickBuilder::resident_set_max_bricks): beyond a few, queueing rays brick
// by brick, which finds each brick's structure in cache, was faster for both
// (docs/BENCHMARKS.md, issue 23).
inline constexpr uint32_t kResidentSetMaxBricks = 16;

class ResidentBrickSet {
 public:
  virtual ~ResidentBrickSet() = default;

  // As BrickAccel::intersect / occluded, over every brick of the set; the
  // engine calls them once per chunk of rays, never per ray.
  virtual void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const = 0;
  virtual void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const = 0;
};

}  // namespace outcore
