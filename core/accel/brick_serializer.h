// BrickSerializer: writes a built brick structure (BrickAccel) to a stream and
// reads it back, for brick structures that support the subtree tier
// (core/cache/subtree_tier.h). Only the payload is the serialiser's; the tier's
// file format (core/cache/subtree_file.h) adds the header and the checksum.
//
// A loaded accel must answer every query bitwise as the built one does and
// report the same memory_bytes(), so the cache's accounting does not depend on
// where a brick came from. A loader may use the bytes in place (no copy) when
// the caller hands it their owner (SerializedBrick::owner, e.g. the mapped
// subtree file): the accel then keeps the owner alive and memory_bytes()
// covers what the owner holds.
//
// Thread-safety: save() and load() may run on many threads at once.
#pragma once

#include <cstdint>
#include <memory>
#include <ostream>
#include <span>
#include <string>

#include "core/accel/brick_accel.h"
#include "core/util/status.h"

namespace outcore {

// Bytes save() wrote, handed back to load().
struct SerializedBrick {
  std::span<const char> bytes;
  // What keeps `bytes` alive. Null: they live only for the load() call, so
  // the accel copies them; set: the accel may keep it and read them in place.
  std::shared_ptr<const void> owner;
  // These exact bytes passed a full load() before (the subtree tier knows the
  // file is unchanged since it wrote or checked it): the structural checks
  // may be skipped. Size and layout are still checked.
  bool known_good = false;
};

class BrickSerializer {
 public:
  virtual ~BrickSerializer() = default;
  // Names the structure, the payload layout's version and every option that
  // changes what the builder makes (e.g. "bvh/1 triangle_test=watertight
  // bins=16 ..."); a tier entry recorded with another key is never used.
  virtual const std::string& structure_key() const = 0;
  // Writes `accel` (made by the builder this serialiser belongs to) to out.
  virtual Status save(const BrickAccel& accel, std::ostream& out) const = 0;
  // Reads what save() wrote for brick `brick_id` of `triangle_count`
  // triangles. A malformed payload is INVALID_ARGUMENT, never a crash.
  virtual Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                                     uint32_t triangle_count) const = 0;
};

}  // namespace outcore
