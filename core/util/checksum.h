// Checksums for stored data: XXH3-64 over manifests and bricks, so a truncated
// or altered file is detected before anything built from it is trusted.
//
// Thread-safety: Checksum64 is a value used by one thread; checksum64() is pure.
#pragma once

#include <xxhash.h>

#include <cstddef>
#include <cstdint>

namespace outcore {

inline uint64_t checksum64(const void* data, std::size_t bytes) {
  return XXH3_64bits(data, bytes);
}

// Incremental form for data written in pieces; gives the same value as
// checksum64() over the concatenation.
class Checksum64 {
 public:
  Checksum64() : state_(XXH3_createState()) { XXH3_64bits_reset(state_); }
  ~Checksum64() { XXH3_freeState(state_); }
  Checksum64(const Checksum64&) = delete;
  Checksum64& operator=(const Checksum64&) = delete;

  void update(const void* data, std::size_t bytes) { XXH3_64bits_update(state_, data, bytes); }
  uint64_t digest() const { return XXH3_64bits_digest(state_); }

 private:
  XXH3_state_t* state_;
};

}  // namespace outcore
