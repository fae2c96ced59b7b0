#include "core/accel/bvh/bvh_brick_serializer.h"

#include <cereal/archives/binary.hpp>

#include <cstdio>
#include <istream>

#include "core/util/span_streambuf.h"

namespace outcore {

BvhBrickSerializer::BvhBrickSerializer(const BvhBrickConfig& config) : config_(config) {
  char key[256];
  std::snprintf(key, sizeof(key),
                "bvh/%d triangle_test=%s bins=%u max_leaf_size=%u traversal_cost=%a "
                "intersection_cost=%a",
                kPayloadVersion, std::string(triangle_test_name(config.triangle_test)).c_str(),
                config.builder.bin_count, config.builder.max_leaf_size,
                static_cast<double>(config.builder.traversal_cost),
                static_cast<double>(config.builder.intersection_cost));
  key_ = key;
}

Status BvhBrickSerializer::save(const BrickAccel& accel, std::ostream& out) const {
  const auto* bvh = dynamic_cast<const BvhBrickAccel*>(&accel);
  if (bvh == nullptr) return invalid_argument("bvh serialiser: the brick is not a bvh brick");
  if (bvh->triangle_test() != config_.triangle_test) {
    return invalid_argument("bvh serialiser: brick " + std::to_string(bvh->brick_id()) +
                            " uses triangle test " + std::string(triangle_test_name(bvh->triangle_test())) +
                            ", not " + std::string(triangle_test_name(config_.triangle_test)));
  }
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(static_cast<uint8_t>(bvh->triangle_test()), bvh->tree());
  } catch (const std::exception& e) {
    return io_error(std::string("bvh serialiser: ") + e.what());
  }
  if (!out) return io_error("bvh serialiser: write failed");
  return Status::Ok();
}

Expected<std::unique_ptr<BrickAccel>> BvhBrickSerializer::load(std::span<const char> payload,
                                                               uint32_t brick_id,
                                                               uint32_t triangle_count) const {
  const std::string what = "bvh serialiser: brick " + std::to_string(brick_id);
  uint8_t test = 0;
  BvhTree tree;
  SpanStreambuf buffer(payload);
  try {
    std::istream in(&buffer);
    cereal::BinaryInputArchive archive(in);
    archive(test, tree);
  } catch (const std::exception& e) {
    return invalid_argument(what + ": cannot read the tree: " + e.what());
  }
  if (buffer.remaining() != 0) {
    return invalid_argument(what + ": " + std::to_string(buffer.remaining()) + " bytes after the tree");
  }
  if (test != static_cast<uint8_t>(config_.triangle_test)) {
    return invalid_argument(what + ": triangle test " + std::to_string(test) + ", expected " +
                            std::string(triangle_test_name(config_.triangle_test)));
  }
  if (tree.triangles.size() > triangle_count) {
    return invalid_argument(what + ": " + std::to_string(tree.triangles.size()) +
                            " triangles, more than the " + std::to_string(triangle_count) + " of the brick");
  }
  const Status valid = tree.validate();
  if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
  return std::unique_ptr<BrickAccel>(
      BvhBrickAccel::from_tree(std::move(tree), config_.triangle_test, brick_id, triangle_count));
}

}  // namespace outcore
