// GridBrickSerializer: the subtree tier's payload for "grid" bricks, version
// 1:
//
//   offset 0   triangle test (uint8), 7 zero bytes
//   offset 8   cell, reference and triangle counts (uint64 each)
//   offset 32  resolution (3 x uint32), 4 zero bytes
//   offset 48  bounds (6 floats: lo xyz, hi xyz), cell width (3 floats),
//              12 zero bytes
//   offset 96  the cell starts (cells + 1, 4 B each), the references (4 B),
//              the triangles (36 B), the hit records (20 B, one per
//              triangle); nothing after
//
// written with cereal's binary archive (little-endian, as the store), under a
// structure key naming the payload version and every GridBrickConfig field.
// load() copies the arrays and validates the grid unless the caller vouches
// for the bytes (SerializedBrick::known_good); counts are checked against the
// builder's budgets for the brick's triangle count and the payload's size
// before anything is allocated.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/brick_serializer.h"
#include "core/accel/grid/grid_brick.h"

namespace outcore {

class GridBrickSerializer final : public BrickSerializer {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit GridBrickSerializer(const GridBrickConfig& config);

  const std::string& structure_key() const override { return key_; }
  Status save(const BrickAccel& accel, std::ostream& out) const override;
  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override;

 private:
  TriangleTest test_;
  std::string key_;
};

}  // namespace outcore
