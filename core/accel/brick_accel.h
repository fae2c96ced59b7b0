// BrickAccel: one brick's built acceleration structure (a "subtree" in the
// design card), as held by the cache. The engine calls it once per brick with
// all the rays queued there, so the virtual call is per brick, never per ray;
// each implementation runs its own tight, non-virtual loop over the rays.
//
// Thread-safety: after construction an accel is immutable; its queries
// may run concurrently from many threads on disjoint ray subsets.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/brick_queries.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_types.h"

namespace outcore {

class BrickAccel {
 public:
  virtual ~BrickAccel() = default;

  // Closest hit: for each i in ray_ids, traces rays[i] over [tnear, min(tfar,
  // hits[i].t)] and replaces hits[i] when hit_is_better() says so. Hit ids are
  // the user's (geometry_id, primitive_id); ng is the unit geometric normal.
  virtual void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const = 0;
  // Any hit: sets occluded[i] = 1 for each ray that hits something in this brick.
  virtual void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const = 0;
  // Every hit (count and list queries): appends (i, hit) to `out` for each
  // triangle of this brick that rays[i] hits with tnear < t <= tfar, once
  // per triangle, for each i in ray_ids (brick_queries.h).
  virtual void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                        std::vector<RayHitRecord>& out) const = 0;
  // Every hit counted only: adds to counts[i] the hits all_hits() would
  // append for ray i. By default through all_hits(); a structure may count
  // without making records.
  virtual void count_hits(std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts) const {
    std::vector<RayHitRecord> found;
    all_hits(ray_ids, rays, found);
    for (const RayHitRecord& r : found) ++counts[r.ray];
  }
  // Closest point: for each i in point_ids, replaces best[i] when a triangle
  // of this brick is nearer to points[i] (closest_is_better).
  virtual void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                              ClosestPoint* best) const = 0;

  // Every byte this brick holds: geometry, index and id buffers, and the
  // acceleration structure (Embree's own allocations, via its memory monitor).
  virtual uint64_t memory_bytes() const = 0;
  virtual double build_seconds() const = 0;
  virtual uint32_t triangle_count() const = 0;
};

}  // namespace outcore
