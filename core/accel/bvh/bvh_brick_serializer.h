// BvhBrickSerializer: the subtree tier's serialiser for "bvh" bricks
// (brick_serializer.h). The payload is a cereal binary archive of the triangle
// test (one byte) and the BvhTree (bvh_tree.h: nodes, reordered triangles, hit
// records as raw little-endian blocks); a loaded tree is validated before use.
// The structure key names the payload version and every BvhBrickConfig field,
// the costs as hexadecimal floats so that equal keys mean equal configs.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <string>

#include "core/accel/brick_serializer.h"
#include "core/accel/bvh/bvh_brick.h"

namespace outcore {

class BvhBrickSerializer final : public BrickSerializer {
 public:
  // Bump when the payload layout or the builder's output for a given config
  // changes, so older tier entries are never used.
  static constexpr int kPayloadVersion = 1;

  explicit BvhBrickSerializer(const BvhBrickConfig& config);

  const std::string& structure_key() const override { return key_; }
  Status save(const BrickAccel& accel, std::ostream& out) const override;
  Expected<std::unique_ptr<BrickAccel>> load(std::span<const char> payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override;

 private:
  BvhBrickConfig config_;
  std::string key_;
};

}  // namespace outcore
