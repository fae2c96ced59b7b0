#include "core/accel/bvh/bvh_brick_serializer.h"

#include <cereal/archives/binary.hpp>

#include <array>
#include <cstdio>
#include <cstring>
#include <ostream>
#include <vector>

namespace outcore {
namespace {

constexpr uint64_t kHeaderBytes = 64;
constexpr uint64_t kMaxArrayElements = uint64_t{1} << 32;

uint64_t align_up(uint64_t offset) {
  constexpr uint64_t kAlign = BvhBrickSerializer::kInPlaceAlignment;
  return (offset + kAlign - 1) / kAlign * kAlign;
}

// Where each array starts and where the payload ends, from the counts.
struct PayloadLayout {
  uint64_t nodes, packets, end;

  static PayloadLayout of(uint64_t node_count, uint64_t packet_count) {
    PayloadLayout layout;
    layout.nodes = kHeaderBytes;
    layout.packets = align_up(layout.nodes + node_count * sizeof(WideBvhNode));
    layout.end = layout.packets + packet_count * sizeof(TrianglePacket);
    return layout;
  }
};

template <class Archive>
void write_zeros(Archive& archive, uint64_t bytes) {
  static constexpr std::array<char, BvhBrickSerializer::kInPlaceAlignment> kZeros{};
  archive(cereal::binary_data(kZeros.data(), bytes));
}

template <class T>
std::span<const T> array_at(std::span<const char> bytes, uint64_t offset, uint64_t count) {
  return {reinterpret_cast<const T*>(bytes.data() + offset), static_cast<std::size_t>(count)};
}

// Fills `out` (already sized) from `bytes` at `offset`; an empty vector's
// data() may be null, which memcpy must not be given even for 0 bytes.
template <class T>
void copy_array(std::vector<T>& out, std::span<const char> bytes, uint64_t offset) {
  if (!out.empty()) std::memcpy(out.data(), bytes.data() + offset, out.size() * sizeof(T));
}

}  // namespace

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
  const WideBvhView& tree = bvh->view();
  const PayloadLayout layout = PayloadLayout::of(tree.nodes.size(), tree.packets.size());
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(static_cast<uint8_t>(bvh->triangle_test()));
    write_zeros(archive, 7);
    archive(static_cast<uint64_t>(tree.nodes.size()), static_cast<uint64_t>(tree.packets.size()));
    write_zeros(archive, kHeaderBytes - 24);
    archive(cereal::binary_data(tree.nodes.data(), tree.nodes.size_bytes()));
    write_zeros(archive, layout.packets - (layout.nodes + tree.nodes.size_bytes()));
    archive(cereal::binary_data(tree.packets.data(), tree.packets.size_bytes()));
  } catch (const std::exception& e) {
    return io_error(std::string("bvh serialiser: ") + e.what());
  }
  if (!out) return io_error("bvh serialiser: write failed");
  return Status::Ok();
}

Expected<std::unique_ptr<BrickAccel>> BvhBrickSerializer::load(const SerializedBrick& payload,
                                                               uint32_t brick_id,
                                                               uint32_t triangle_count) const {
  const std::string what = "bvh serialiser: brick " + std::to_string(brick_id);
  const std::span<const char> bytes = payload.bytes;
  if (bytes.size() < kHeaderBytes) {
    return invalid_argument(what + ": truncated (" + std::to_string(bytes.size()) + " bytes, no header)");
  }
  const uint8_t test = static_cast<uint8_t>(bytes[0]);
  uint64_t counts[2];
  std::memcpy(counts, bytes.data() + 8, sizeof(counts));
  for (const uint64_t count : counts) {
    if (count > kMaxArrayElements) {
      return invalid_argument(what + ": an array of " + std::to_string(count) + " elements");
    }
  }
  const PayloadLayout layout = PayloadLayout::of(counts[0], counts[1]);
  if (layout.end > bytes.size()) {
    return invalid_argument(what + ": truncated (" + std::to_string(bytes.size()) +
                            " bytes, the tree needs " + std::to_string(layout.end) + ")");
  }
  if (layout.end < bytes.size()) {
    return invalid_argument(what + ": " + std::to_string(bytes.size() - layout.end) +
                            " bytes after the tree");
  }
  if (test != static_cast<uint8_t>(config_.triangle_test)) {
    return invalid_argument(what + ": triangle test " + std::to_string(test) + ", expected " +
                            std::string(triangle_test_name(config_.triangle_test)));
  }
  // Slots: the triangles plus at most a quarter of padding, plus a packet.
  const uint64_t max_packets = (uint64_t{triangle_count} + triangle_count / 4 + 8) / kPacketLanes + 2;
  if (counts[1] > max_packets) {
    return invalid_argument(what + ": " + std::to_string(counts[1]) + " triangle packets, more than the " +
                            std::to_string(triangle_count) + " triangles of the brick can fill");
  }
  const bool in_place =
      payload.owner != nullptr && reinterpret_cast<uintptr_t>(bytes.data()) % kInPlaceAlignment == 0;
  WideBvh copy;
  WideBvhView view;
  if (in_place) {
    view = {array_at<WideBvhNode>(bytes, layout.nodes, counts[0]),
            array_at<TrianglePacket>(bytes, layout.packets, counts[1])};
  } else {
    // Unaligned or short-lived bytes: the accel gets its own copy.
    copy.nodes.resize(counts[0]);
    copy.packets.resize(counts[1]);
    copy_array(copy.nodes, bytes, layout.nodes);
    copy_array(copy.packets, bytes, layout.packets);
    view = copy.view();
  }
  if (!payload.known_good) {
    const Status valid = view.validate();
    if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
  }
  if (in_place) {
    return std::unique_ptr<BrickAccel>(
        BvhBrickAccel::from_view(view, payload.owner, config_.triangle_test, brick_id, triangle_count));
  }
  return std::unique_ptr<BrickAccel>(
      BvhBrickAccel::from_tree(std::move(copy), config_.triangle_test, brick_id, triangle_count));
}

}  // namespace outcore
