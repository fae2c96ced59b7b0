// BspBrickAccel: a brick's triangles in an SAH restricted BSP tree
// (bsp_tree_builder.h: planes along 3, 7 or 13 fixed orientations) traced by
// the kd-tree's front-to-back stack walk (bsp_tree_traversal.h) with the
// triangle test chosen by name, and BspBrickBuilder, the BrickBuilder that
// makes them (registered as "bsp" in brick_accel_factory.cpp).
//
// Hits follow the bvh brick's contract (bvh_brick.h): tnear < t <= tfar, the
// user's ids, Embree's barycentrics, the float64 normal rounded, ties to the
// smaller (geometry_id, primitive_id); degenerate or non-finite triangles are
// left out. BspBrickSerializer (bsp_brick_serializer.h) keeps them in the
// subtree tier.
//
// Memory: memory_bytes() = the tree's arrays (8 B per node, 4 B per
// reference, 56 B per triangle) + kOverheadBytes; reserve_bytes(n) bounds it
// and the build's peak (the builder caps references at
// BspTreeBuilder::kMaxReferencesPerTriangle per triangle).
//
// Thread-safety: build() may run on many threads at once; a built accel is
// immutable and intersect() / occluded() may run concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/accel/brick_accel_factory.h"
#include "core/accel/bsp/bsp_tree.h"
#include "core/accel/bsp/bsp_tree_builder.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/store/brick_data.h"

namespace outcore {

struct BspBrickConfig {
  TriangleTest triangle_test = TriangleTest::kWatertight;
  BspTreeBuilder::Config builder;
};

class BspBrickAccel final : public BrickAccel {
 public:
  // Node indices and reference counts must fit 28 bits (kMaxBspIndex) under
  // the builder's budgets (16 nodes a triangle at most).
  static constexpr uint64_t kMaxTriangles = 1u << 23;
  static constexpr uint64_t kOverheadBytes = 8192;

  // Consumes the brick. INVALID_ARGUMENT when ids and triangles differ in
  // count or the config is invalid, OUT_OF_RANGE beyond kMaxTriangles.
  static Expected<std::unique_ptr<BspBrickAccel>> build(BrickData&& brick, const BspBrickConfig& config);
  // A brick from a tree it owns; the tree must be valid (validate()).
  // triangle_count: the source brick's, degenerate triangles included.
  static std::unique_ptr<BspBrickAccel> from_tree(BspTree tree, TriangleTest test, uint32_t brick_id,
                                                  uint32_t triangle_count);
  static uint64_t reserve_bytes(uint64_t triangle_count);

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;

  uint64_t memory_bytes() const override { return tree_.memory_bytes() + kOverheadBytes; }
  double build_seconds() const override { return build_seconds_; }
  uint32_t triangle_count() const override { return triangle_count_; }

  // Beyond BrickAccel (statistics and tests):
  BspTreeView view() const { return tree_.view(); }
  uint64_t build_peak_bytes() const { return build_peak_bytes_; }
  TriangleTest triangle_test() const { return test_; }
  uint32_t brick_id() const { return brick_id_; }

 private:
  BspBrickAccel() = default;

  BspTree tree_;
  TriangleTest test_ = TriangleTest::kWatertight;
  uint32_t triangle_count_ = 0;  // including the degenerate ones left out
  uint32_t brick_id_ = 0;
  uint64_t build_peak_bytes_ = 0;
  double build_seconds_ = 0;
};

class BspBrickSerializer;

class BspBrickBuilder final : public BrickBuilder {
 public:
  explicit BspBrickBuilder(const BspBrickConfig& config);
  ~BspBrickBuilder() override;

  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override;
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return BspBrickAccel::reserve_bytes(triangle_count);
  }
  const std::string& name() const override;
  const BrickSerializer* serializer() const override;
  double hit_rounding_scale() const override {
    return config_.triangle_test == TriangleTest::kMt ? kMollerTrumboreHitRounding : kWatertightHitRounding;
  }
  const BspBrickConfig& config() const { return config_; }

 private:
  BspBrickConfig config_;
  std::unique_ptr<const BspBrickSerializer> serializer_;  // bsp_brick_serializer.h
};

}  // namespace outcore
