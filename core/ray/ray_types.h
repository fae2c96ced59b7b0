// Ray and Hit: what a query sends and gets back, laid out exactly like the
// contract's files so they can be read and written without conversion: a ray
// is `ox oy oz dx dy dz tnear tfar` (float32); a hit is the 32-byte record of
// the hits .npy (t_hit, geometry_id, primitive_id, u, v, ng[3]).
//
// Thread-safety: plain values.
#pragma once

#include <cstdint>
#include <limits>

#include "core/geometry/vec3.h"

namespace outcore {

inline constexpr uint32_t kInvalidId = 0xffffffffu;

// The largest |component| of a ray's origin or direction the engine traces:
// Embree's FLT_LARGE, beyond which rtcIntersect asserts (and a Debian build
// of Embree aborts the process). Larger finite components make a ray invalid.
inline constexpr float kLargestRayComponent = 1.844e18f;

struct Ray {
  Vec3f origin;
  Vec3f direction;  // need not be unit length; t is in units of its length
  float tnear = 0.0f;
  float tfar = std::numeric_limits<float>::infinity();
};
static_assert(sizeof(Ray) == 32);

struct Hit {
  float t = std::numeric_limits<float>::infinity();  // inf on a miss
  uint32_t geometry_id = kInvalidId;
  uint32_t primitive_id = kInvalidId;
  float u = 0.0f;  // barycentrics: p = (1-u-v) v0 + u v1 + v v2
  float v = 0.0f;
  Vec3f normal;  // unit geometric normal; zeros on a miss

  bool is_hit() const { return primitive_id != kInvalidId; }
};
static_assert(sizeof(Hit) == 32);

}  // namespace outcore
