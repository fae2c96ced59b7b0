// HgridBrickSerializer: the subtree tier's payload for "hgrid" bricks,
// version 1:
//
//   offset 0   triangle test (uint8), 7 zero bytes
//   offset 8   grid, cell, reference and triangle counts (uint64 each)
//   offset 40  24 zero bytes
//   offset 64  the grids (36 B each: box as 6 floats, first cell uint32,
//              resolution 3 x uint16, 2 zero bytes), the cells (8 B each:
//              first reference or nested grid, bits), the references
//              (4 B), the triangles (36 B), the hit records (20 B, one per
//              triangle); nothing after
//
// written with cereal's binary archive (little-endian, as the store), under a
// structure key naming the payload version and every HgridBrickConfig
// field. Cell widths are not stored: GridLattice::over() makes them from
// box and resolution, as the build did. load() copies the arrays and
// validates the grid unless the caller vouches for the bytes
// (SerializedBrick::known_good); counts are checked against the builder's
// budgets for the brick's triangle count and the payload's size before
// anything is allocated.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/brick_serializer.h"
#include "core/accel/hgrid/hgrid_brick.h"

namespace outcore {

class HgridBrickSerializer final : public BrickSerializer {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit HgridBrickSerializer(const HgridBrickConfig& config);

  const std::string& structure_key() const override { return key_; }
  Status save(const BrickAccel& accel, std::ostream& out) const override;
  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override;

 private:
  TriangleTest test_;
  std::string key_;
};

}  // namespace outcore
