// BvhBrickSerializer: the subtree tier's serialiser for "bvh" bricks
// (brick_serializer.h). The payload (version 4) is laid out so that a mapped
// file can be traversed in place, without copying or parsing the arrays:
//
//   offset 0   triangle test (uint8), 7 zero bytes
//   offset 8   node count, packet count (uint64 each)
//   offset 24  40 zero bytes
//   offset 64  the wide nodes (256 B each), then the triangle packets (352 B
//              each, starting on a multiple of 64); nothing after them
//
// written with cereal's binary archive (little-endian, as the store). load()
// uses the arrays in place when the payload starts on a 64-byte boundary and
// the caller hands over its owner (the subtree file puts the payload on one),
// else it copies them; either way the tree is validated first unless the
// caller vouches for the bytes (SerializedBrick::known_good). The structure
// key names the payload version and every BvhBrickConfig field, the costs as
// hexadecimal floats so that equal keys mean equal configs.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <cstddef>
#include <string>

#include "core/accel/brick_serializer.h"
#include "core/accel/bvh/bvh_brick.h"

namespace outcore {

class BvhBrickSerializer final : public BrickSerializer {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 4;
  // Where the payload must start for load() to use it in place.
  static constexpr std::size_t kInPlaceAlignment = 64;

  explicit BvhBrickSerializer(const BvhBrickConfig& config);

  const std::string& structure_key() const override { return key_; }
  Status save(const BrickAccel& accel, std::ostream& out) const override;
  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override;

 private:
  BvhBrickConfig config_;
  std::string key_;
};

}  // namespace outcore
