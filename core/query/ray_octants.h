// RayOctants: the direction octant of each ray of a first-pass chunk, one
// byte a ray, and the test whether eight consecutive rays can walk the upper
// hierarchy as one packet (their valid ones share an octant). The queued
// first pass tries a packet at every ray; testing eight bytes at once, with
// no branch per ray, keeps that try cheap for incoherent rays, whose octants
// differ at random (a branch per ray mispredicted about every other ray).
//
// Thread-safety: one per task; a plain value.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/ray/ray_types.h"

namespace outcore {

template <std::size_t kRays>
class RayOctants {
 public:
  // Ray k's octant (bit a: the direction's sign on axis a), or invalid.
  void set(std::size_t k, const Ray& ray) {
    const Vec3f& d = ray.direction;
    octant_[k] = static_cast<uint8_t>(int(std::signbit(d.x)) | int(std::signbit(d.y)) << 1 |
                                      int(std::signbit(d.z)) << 2);
  }
  void set_invalid(std::size_t k) { octant_[k] = kInvalid; }

  // The valid rays among k .. k+7 (bit j for ray k+j) when there are at
  // least two and they share an octant; 0 otherwise. k + 8 <= kRays.
  uint32_t packet_lanes(std::size_t k) const {
#if defined(__SSE2__)
    const __m128i bytes = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(octant_ + k));
    // Octants are 0..7: only kInvalid has its high bit set.
    const uint32_t lanes = ~static_cast<uint32_t>(_mm_movemask_epi8(bytes)) & 0xFFu;
    if (__builtin_popcount(lanes) < 2) return 0;
    const char octant = static_cast<char>(octant_[k + static_cast<std::size_t>(__builtin_ctz(lanes))]);
    const uint32_t same =
        static_cast<uint32_t>(_mm_movemask_epi8(_mm_cmpeq_epi8(bytes, _mm_set1_epi8(octant))));
    return (same & lanes) == lanes ? lanes : 0;
#else
    uint32_t lanes = 0;
    int octant = -1;
    for (uint32_t j = 0; j < 8; ++j) {
      const uint8_t o = octant_[k + j];
      if (o == kInvalid) continue;
      if (octant >= 0 && o != octant) return 0;
      octant = o;
      lanes |= 1u << j;
    }
    return __builtin_popcount(lanes) < 2 ? 0 : lanes;
#endif
  }

 private:
  static constexpr uint8_t kInvalid = 0xFF;
  uint8_t octant_[kRays];
};

}  // namespace outcore
