// Per-ray working state shared by the engine and the brick structures: the
// current closest hit of every ray of a batch. Brick structures update it
// through accept_hit(), whose tie rule makes the answer independent of the
// order bricks are visited in.
//
// Thread-safety: a RayState is written by one thread at a time (the engine
// hands each ray to one task per brick).
#pragma once

#include <cstdint>

#include "core/ray/ray_types.h"

namespace outcore {

// Closest hit so far. Ties at equal t go to the smaller (geometry_id,
// primitive_id), between bricks and inside one (the embree brick's tie
// filter, embree_brick.h), so the result is the same whatever order bricks
// come in and whichever path (packet or single ray) traced the ray.
inline bool hit_is_better(float t, uint32_t geometry_id, uint32_t primitive_id, const Hit& current) {
  if (t != current.t) return t < current.t;
  if (geometry_id != current.geometry_id) return geometry_id < current.geometry_id;
  return primitive_id < current.primitive_id;
}

// kAllHits: every hit along each ray (count and list queries).
enum class QueryKind { kClosestHit, kAnyHit, kAllHits };

}  // namespace outcore
