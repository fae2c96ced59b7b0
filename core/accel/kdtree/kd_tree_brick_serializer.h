// KdTreeBrickSerializer: the subtree tier's serialiser for "kdtree" bricks
// (brick_serializer.h). The payload (version 1):
//
//   offset 0   triangle test (uint8), 7 zero bytes
//   offset 8   node, reference and triangle counts (uint64 each)
//   offset 32  the tree's bounds (6 floats: lo xyz, hi xyz), 8 zero bytes
//   offset 64  the nodes (8 B each), the references (4 B), the triangles
//              (36 B), the hit records (20 B, one per triangle); nothing after
//
// written with cereal's binary archive (little-endian, as the store). load()
// always copies the arrays (a kd-tree brick is small next to its build, and
// a copy keeps memory_bytes() the same as a built brick's) and validates the
// tree unless the caller vouches for the bytes (SerializedBrick::known_good);
// every count is checked against the payload's size before anything is
// allocated. The structure key names the payload version and every
// KdTreeBrickConfig field, the costs as hexadecimal floats so that equal keys
// mean equal configs.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/brick_serializer.h"
#include "core/accel/kdtree/kd_tree_brick.h"

namespace outcore {

class KdTreeBrickSerializer final : public BrickSerializer {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit KdTreeBrickSerializer(const KdTreeBrickConfig& config);

  const std::string& structure_key() const override { return key_; }
  Status save(const BrickAccel& accel, std::ostream& out) const override;
  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override;

 private:
  KdTreeBrickConfig config_;
  std::string key_;
};

}  // namespace outcore
