// BvhBrickAccel: a brick's triangles in our own BVH — built binary by binned
// SAH (binned_sah_builder.h), collapsed to 8-wide nodes and packets of 8
// triangles (wide_bvh_collapse.h) — traced with the triangle test chosen by
// name (TriangleTest) on the SIMD path of the CPU (wide_bvh_trace.h), and
// BvhBrickBuilder, the BrickBuilder that makes them (registered as "bvh" in
// brick_accel_factory.cpp).
//
// Hits follow the same contract as the embree brick: a hit at t counts when
// tnear < t <= tfar; ids are the user's; u, v are Embree's barycentrics
// (p = (1-u-v) v0 + u v1 + v v2); the normal is normalize(cross(v1 - v0,
// v2 - v0)) computed in float64 and rounded (Embree's Ng orientation);
// ties at equal t go to the smaller (geometry_id, primitive_id)
// (hit_is_better). Triangles that are degenerate in float64 (or not finite)
// are left out: the float64 reference never hits them.
//
// The test and the SIMD path are selected once per brick call (one switch),
// then a loop over the rays calls the traversal templated on them: no
// per-ray dispatch.
//
// Memory: memory_bytes() = the tree's arrays (256 B per wide node, 352 B per
// packet of 8 triangles, about 50 B per triangle in all) + kOverheadBytes,
// whether the accel owns them (a build) or reads them in place from a loaded
// subtree file (from_view(); kOverheadBytes also covers such a file's header,
// padding, trailer and last partial page). reserve_bytes(n) bounds it and
// the build peak (see bvh_brick.cpp).
//
// Thread-safety: build() may run on many threads at once; a built accel is
// immutable and intersect() / occluded() may run concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "core/accel/brick_accel_factory.h"
#include "core/accel/bvh/binned_sah_builder.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/wide_bvh.h"
#include "core/store/brick_data.h"

namespace outcore {

struct BvhBrickConfig {
  // Default watertight: zero leaks through shared edges and vertices (the
  // stress suite), at a small cost over mt; double is the accuracy reference.
  TriangleTest triangle_test = TriangleTest::kWatertight;
  BinnedSahBuilder::Config builder;
};

class BvhBrickAccel final : public BrickAccel {
 public:
  static constexpr uint64_t kMaxTriangles = 0xfffffffeu;
  // This object and what the allocator keeps per allocation, or a mapped
  // subtree file's bytes beyond the arrays (header with the structure key,
  // alignment padding, checksum, the rest of the last page), with margin.
  static constexpr uint64_t kOverheadBytes = 8192;

  // Consumes the brick. INVALID_ARGUMENT when ids and triangles differ in
  // count or the config is invalid, OUT_OF_RANGE beyond kMaxTriangles.
  static Expected<std::unique_ptr<BvhBrickAccel>> build(BrickData&& brick, const BvhBrickConfig& config);
  // A brick from a tree it owns; the tree must be valid (validate()).
  // triangle_count: the source brick's, degenerate triangles included (the
  // tree holds only the usable ones).
  static std::unique_ptr<BvhBrickAccel> from_tree(WideBvh tree, TriangleTest test, uint32_t brick_id,
                                                  uint32_t triangle_count);
  // A brick that reads a valid view in place; `owner` keeps the viewed bytes
  // alive (e.g. a subtree file's copy) for as long as the accel lives.
  static std::unique_ptr<BvhBrickAccel> from_view(const WideBvhView& view, std::shared_ptr<const void> owner,
                                                  TriangleTest test, uint32_t brick_id,
                                                  uint32_t triangle_count);
  // Upper bound on memory_bytes() and build_peak_bytes() for n triangles.
  static uint64_t reserve_bytes(uint64_t triangle_count);

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;
  void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                std::vector<RayHitRecord>& out) const override;
  void count_hits(std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts) const override;
  void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                      ClosestPoint* best) const override;

  uint64_t memory_bytes() const override { return memory_bytes_; }
  double build_seconds() const override { return build_seconds_; }
  uint32_t triangle_count() const override { return triangle_count_; }

  // Beyond BrickAccel (statistics and tests):
  const WideBvhView& view() const { return view_; }
  // Whether the arrays are read in place from bytes someone else owns.
  bool in_place() const { return owner_ != nullptr; }
  TriangleTest triangle_test() const { return test_; }
  uint32_t brick_id() const { return brick_id_; }
  uint64_t build_peak_bytes() const { return build_peak_bytes_; }

 private:
  BvhBrickAccel() = default;

  WideBvh tree_;                       // empty when in place
  std::shared_ptr<const void> owner_;  // of the bytes view_ reads, when in place
  WideBvhView view_;
  uint64_t memory_bytes_ = kOverheadBytes;
  TriangleTest test_ = TriangleTest::kWatertight;
  uint32_t brick_id_ = 0;
  uint32_t triangle_count_ = 0;  // including the degenerate ones left out
  uint64_t build_peak_bytes_ = 0;
  double build_seconds_ = 0;
};

class BvhBrickSerializer;

class BvhBrickBuilder final : public BrickBuilder {
 public:
  explicit BvhBrickBuilder(const BvhBrickConfig& config);
  ~BvhBrickBuilder() override;

  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override;
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return BvhBrickAccel::reserve_bytes(triangle_count);
  }
  const std::string& name() const override;
  const BrickSerializer* serializer() const override;
  double hit_rounding_scale() const override {
    return config_.triangle_test == TriangleTest::kMt ? kMollerTrumboreHitRounding : kWatertightHitRounding;
  }
  // The resident bricks as one structure (BvhBrickSet; defined in
  // bvh_brick_set.cpp), a two-level BVH: it would serve any number of
  // bricks, but is offered for kResidentSetMaxBricks.
  uint32_t resident_set_max_bricks() const override { return kResidentSetMaxBricks; }
  Expected<std::unique_ptr<ResidentBrickSet>> make_resident_set(
      std::span<const BrickAccel* const> bricks) const override;
  const BvhBrickConfig& config() const { return config_; }

 private:
  BvhBrickConfig config_;
  std::unique_ptr<const BvhBrickSerializer> serializer_;  // bvh_brick_serializer.h
};

}  // namespace outcore
