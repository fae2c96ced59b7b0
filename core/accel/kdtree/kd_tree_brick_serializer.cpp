#include "core/accel/kdtree/kd_tree_brick_serializer.h"

#include <cereal/archives/binary.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ostream>
#include <vector>

namespace outcore {
namespace {

constexpr uint64_t kHeaderBytes = 64;
constexpr uint64_t kBoundsOffset = 32;

// Where each array starts and where the payload ends, from the counts (each
// already checked small enough that the sums cannot overflow).
struct PayloadLayout {
  uint64_t nodes, refs, triangles, records, end;

  static PayloadLayout of(uint64_t node_count, uint64_t ref_count, uint64_t triangle_count) {
    PayloadLayout layout;
    layout.nodes = kHeaderBytes;
    layout.refs = layout.nodes + node_count * sizeof(KdNode);
    layout.triangles = layout.refs + ref_count * sizeof(uint32_t);
    layout.records = layout.triangles + triangle_count * sizeof(Triangle);
    layout.end = layout.records + triangle_count * sizeof(BvhHitRecord);
    return layout;
  }
};

template <class Archive>
void write_zeros(Archive& archive, uint64_t bytes) {
  static constexpr std::array<char, kHeaderBytes> kZeros{};
  archive(cereal::binary_data(kZeros.data(), bytes));
}

template <class Archive, class T>
void write_array(Archive& archive, std::span<const T> values) {
  if (!values.empty()) archive(cereal::binary_data(values.data(), values.size_bytes()));
}

// `out` resized to `count` and filled from `bytes` at `offset`; an empty
// vector's data() may be null, which memcpy must not be given even for 0 bytes.
template <class T>
void read_array(std::vector<T>& out, uint64_t count, std::span<const char> bytes, uint64_t offset) {
  out.resize(count);
  if (!out.empty()) std::memcpy(out.data(), bytes.data() + offset, out.size() * sizeof(T));
}

}  // namespace

KdTreeBrickSerializer::KdTreeBrickSerializer(const KdTreeBrickConfig& config) : config_(config) {
  char key[256];
  std::snprintf(key, sizeof(key),
                "kdtree/%d triangle_test=%s traversal_cost=%a intersection_cost=%a empty_bonus=%a "
                "max_depth=%u",
                kPayloadVersion, std::string(triangle_test_name(config.triangle_test)).c_str(),
                static_cast<double>(config.builder.traversal_cost),
                static_cast<double>(config.builder.intersection_cost),
                static_cast<double>(config.builder.empty_bonus), config.builder.max_depth);
  key_ = key;
}

Status KdTreeBrickSerializer::save(const BrickAccel& accel, std::ostream& out) const {
  const auto* kd = dynamic_cast<const KdTreeBrickAccel*>(&accel);
  if (kd == nullptr) return invalid_argument("kdtree serialiser: the brick is not a kdtree brick");
  if (kd->triangle_test() != config_.triangle_test) {
    return invalid_argument("kdtree serialiser: brick " + std::to_string(kd->brick_id()) +
                            " uses triangle test " + std::string(triangle_test_name(kd->triangle_test())) +
                            ", not " + std::string(triangle_test_name(config_.triangle_test)));
  }
  const KdTreeView tree = kd->view();
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(static_cast<uint8_t>(kd->triangle_test()));
    write_zeros(archive, 7);
    archive(static_cast<uint64_t>(tree.nodes.size()), static_cast<uint64_t>(tree.refs.size()),
            static_cast<uint64_t>(tree.triangles.size()));
    const std::array<float, 6> bounds{tree.bounds.lo.x, tree.bounds.lo.y, tree.bounds.lo.z,
                                      tree.bounds.hi.x, tree.bounds.hi.y, tree.bounds.hi.z};
    archive(cereal::binary_data(bounds.data(), sizeof(bounds)));
    write_zeros(archive, kHeaderBytes - kBoundsOffset - sizeof(bounds));
    write_array(archive, tree.nodes);
    write_array(archive, tree.refs);
    write_array(archive, tree.triangles);
    write_array(archive, tree.records);
  } catch (const std::exception& e) {
    return io_error(std::string("kdtree serialiser: ") + e.what());
  }
  if (!out) return io_error("kdtree serialiser: write failed");
  return Status::Ok();
}

Expected<std::unique_ptr<BrickAccel>> KdTreeBrickSerializer::load(const SerializedBrick& payload,
                                                                  uint32_t brick_id,
                                                                  uint32_t triangle_count) const {
  const std::string what = "kdtree serialiser: brick " + std::to_string(brick_id);
  const std::span<const char> bytes = payload.bytes;
  if (bytes.size() < kHeaderBytes) {
    return invalid_argument(what + ": truncated (" + std::to_string(bytes.size()) + " bytes, no header)");
  }
  const uint8_t test = static_cast<uint8_t>(bytes[0]);
  if (test != static_cast<uint8_t>(config_.triangle_test)) {
    return invalid_argument(what + ": triangle test " + std::to_string(test) + ", expected " +
                            std::string(triangle_test_name(config_.triangle_test)));
  }
  uint64_t counts[3];
  std::memcpy(counts, bytes.data() + 8, sizeof(counts));
  // The budgets the builder keeps (kd_tree_builder.h), so that a payload
  // cannot claim more than a build of this brick could have made.
  const uint64_t max_refs = KdTreeBuilder::kMaxReferencesPerTriangle * uint64_t{triangle_count} + 64;
  const uint64_t max_nodes = 4 * max_refs + 1;
  if (counts[2] > triangle_count) {
    return invalid_argument(what + ": " + std::to_string(counts[2]) + " triangles, more than the brick's " +
                            std::to_string(triangle_count));
  }
  if (counts[1] > max_refs || counts[0] > max_nodes) {
    return invalid_argument(what + ": " + std::to_string(counts[0]) + " nodes and " +
                            std::to_string(counts[1]) + " references, more than a tree of " +
                            std::to_string(triangle_count) + " triangles holds");
  }
  const PayloadLayout layout = PayloadLayout::of(counts[0], counts[1], counts[2]);
  if (layout.end != bytes.size()) {
    return invalid_argument(what + ": " + std::to_string(bytes.size()) + " bytes, the tree's counts need " +
                            std::to_string(layout.end));
  }
  KdTree tree;
  float bounds[6];
  std::memcpy(bounds, bytes.data() + kBoundsOffset, sizeof(bounds));
  tree.bounds.lo = {bounds[0], bounds[1], bounds[2]};
  tree.bounds.hi = {bounds[3], bounds[4], bounds[5]};
  read_array(tree.nodes, counts[0], bytes, layout.nodes);
  read_array(tree.refs, counts[1], bytes, layout.refs);
  read_array(tree.triangles, counts[2], bytes, layout.triangles);
  read_array(tree.records, counts[2], bytes, layout.records);
  if (!payload.known_good) {
    for (const float b : bounds) {
      if (std::isnan(b)) return invalid_argument(what + ": the tree's bounds are NaN");
    }
    const Status valid = tree.view().validate();
    if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
  }
  return std::unique_ptr<BrickAccel>(
      KdTreeBrickAccel::from_tree(std::move(tree), config_.triangle_test, brick_id, triangle_count));
}

}  // namespace outcore
