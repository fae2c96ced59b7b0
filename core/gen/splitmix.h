// mix64: the splitmix64 finaliser, the integer hash behind every generator's
// seeded randomness (city transforms, terrain noise lattice).
//
// Thread-safety: pure function.
#pragma once

#include <cstdint>

namespace outcore {

inline uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  x ^= x >> 31;
  return x;
}

}  // namespace outcore
