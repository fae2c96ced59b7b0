// SplitTreeSerializer: the subtree tier's payload for the split-plane trees
// (the kd-tree, the BSP, the octree and the quadtree, which share their
// layout: bounds, nodes (8 bytes; the quadtree's 16),
// references, triangles, hit records), version 1:
//
//   offset 0   triangle test (uint8), 7 zero bytes
//   offset 8   node, reference and triangle counts (uint64 each)
//   offset 32  the tree's bounds (6 floats: lo xyz, hi xyz), 8 zero bytes
//   offset 64  the nodes (sizeof(Node) each), the references (4 B), the triangles
//              (36 B), the hit records (20 B, one per triangle); nothing after
//
// written with cereal's binary archive (little-endian, as the store). load()
// always copies the arrays (a tree is small next to its build, and a copy
// keeps memory_bytes() the same as a built brick's) and validates the tree
// unless the caller vouches for the bytes (SerializedBrick::known_good);
// every count is checked against the builder's budgets for the brick's
// triangle count and the payload's size before anything is allocated.
//
// Traits name the structure ("kdtree", "bsp") and give its Accel (view(),
// triangle_test(), brick_id(), from_tree()), Tree, Node and the builder's
// references per triangle. KdTreeBrickSerializer and BspBrickSerializer are
// the two instances; each adds its structure key.
//
// Thread-safety: immutable after construction; save() and load() may run on
// many threads at once.
#pragma once

#include <cereal/archives/binary.hpp>

#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "core/accel/brick_serializer.h"
#include "core/accel/bvh/bvh_tree.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/payload_io.h"
#include "core/geometry/triangle.h"

namespace outcore {

template <class Traits>
class SplitTreeSerializer : public BrickSerializer {
 public:
  using Accel = typename Traits::Accel;
  using Tree = typename Traits::Tree;
  using Node = typename Traits::Node;

  SplitTreeSerializer(TriangleTest test, std::string key) : test_(test), key_(std::move(key)) {}

  const std::string& structure_key() const override { return key_; }

  Status save(const BrickAccel& accel, std::ostream& out) const override {
    const std::string name = std::string(Traits::kName) + " serialiser";
    OUTCORE_ASSIGN_OR_RETURN(const Accel* tree_accel,
                             payload_io::brick_to_save<Accel>(accel, test_, name, Traits::kName));
    const auto tree = tree_accel->view();
    try {
      cereal::BinaryOutputArchive archive(out);
      archive(static_cast<uint8_t>(test_));
      payload_io::write_zeros(archive, 7);
      archive(static_cast<uint64_t>(tree.nodes.size()), static_cast<uint64_t>(tree.refs.size()),
              static_cast<uint64_t>(tree.triangles.size()));
      const std::array<float, 6> bounds{tree.bounds.lo.x, tree.bounds.lo.y, tree.bounds.lo.z,
                                        tree.bounds.hi.x, tree.bounds.hi.y, tree.bounds.hi.z};
      archive(cereal::binary_data(bounds.data(), sizeof(bounds)));
      payload_io::write_zeros(archive, kHeaderBytes - kBoundsOffset - sizeof(bounds));
      payload_io::write_array(archive, tree.nodes);
      payload_io::write_array(archive, tree.refs);
      payload_io::write_array(archive, tree.triangles);
      payload_io::write_array(archive, tree.records);
    } catch (const std::exception& e) {
      return io_error(name + ": " + e.what());
    }
    if (!out) return io_error(name + ": write failed");
    return Status::Ok();
  }

  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override {
    const std::string what = std::string(Traits::kName) + " serialiser: brick " + std::to_string(brick_id);
    const std::span<const char> bytes = payload.bytes;
    OUTCORE_RETURN_IF_ERROR(payload_io::check_header(bytes, kHeaderBytes, test_, what));
    uint64_t counts[3];
    std::memcpy(counts, bytes.data() + 8, sizeof(counts));
    // The builder's budgets: a payload cannot claim more than a build of this
    // brick could have made.
    const uint64_t max_refs = Traits::kMaxReferencesPerTriangle * uint64_t{triangle_count} + 64;
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
    const uint64_t refs_at = kHeaderBytes + counts[0] * sizeof(Node);
    const uint64_t triangles_at = refs_at + counts[1] * sizeof(uint32_t);
    const uint64_t records_at = triangles_at + counts[2] * sizeof(Triangle);
    const uint64_t end = records_at + counts[2] * sizeof(BvhHitRecord);
    if (end != bytes.size()) {
      return invalid_argument(what + ": " + std::to_string(bytes.size()) + " bytes, the tree's counts need " +
                              std::to_string(end));
    }
    Tree tree;
    float bounds[6];
    std::memcpy(bounds, bytes.data() + kBoundsOffset, sizeof(bounds));
    tree.bounds.lo = {bounds[0], bounds[1], bounds[2]};
    tree.bounds.hi = {bounds[3], bounds[4], bounds[5]};
    payload_io::read_array(tree.nodes, counts[0], bytes, kHeaderBytes);
    payload_io::read_array(tree.refs, counts[1], bytes, refs_at);
    payload_io::read_array(tree.triangles, counts[2], bytes, triangles_at);
    payload_io::read_array(tree.records, counts[2], bytes, records_at);
    if (!payload.known_good) {
      for (const float b : bounds) {
        if (std::isnan(b)) return invalid_argument(what + ": the tree's bounds are NaN");
      }
      const Status valid = tree.view().validate();
      if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
    }
    return std::unique_ptr<BrickAccel>(Accel::from_tree(std::move(tree), test_, brick_id, triangle_count));
  }

 private:
  static constexpr uint64_t kHeaderBytes = 64;
  static constexpr uint64_t kBoundsOffset = 32;

  TriangleTest test_;
  std::string key_;
};

}  // namespace outcore
