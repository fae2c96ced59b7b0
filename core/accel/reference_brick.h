// ReferenceBrickAccel: ground truth for one brick — every ray tested against
// every triangle of the brick in float64, with the watertight test carried out
// in double (double_triangle_test.h; so a ray through a shared vertex or edge
// never falls between triangles, which float64 Möller–Trumbore can), no
// boxes, no culling. Registered as "reference" in brick_accel_factory.cpp and
// used by `outcore trace --reference`, so the ground truth comes from the
// same store, bricks, upper hierarchy and engine as the answer it checks.
// Slow by design: O(rays x triangles) per brick.
//
// Same contract as the other structures: tnear < t <= tfar (decided on the
// double t), user ids, Embree barycentrics, unit float64 normal rounded,
// ties by hit_is_better on the rounded t. Degenerate (float64) and non-finite
// triangles are never hit.
//
// Thread-safety: immutable after build; intersect() / occluded() concurrent.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/accel/bvh/bvh_tree.h"
#include "core/store/brick_data.h"

namespace outcore {

class ReferenceBrickAccel final : public BrickAccel {
 public:
  static constexpr uint64_t kOverheadBytes = 256;

  static Expected<std::unique_ptr<ReferenceBrickAccel>> build(BrickData&& brick);
  // Keeps the brick's vectors (their capacity) and a normal per triangle.
  static uint64_t reserve_bytes(uint64_t triangle_count) {
    return kOverheadBytes + triangle_count * (sizeof(Triangle) + sizeof(BvhHitRecord));
  }

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;
  void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                std::vector<RayHitRecord>& out) const override;
  void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                      ClosestPoint* best) const override;
  uint64_t memory_bytes() const override;
  double build_seconds() const override { return build_seconds_; }
  uint32_t triangle_count() const override { return triangle_count_; }

 private:
  ReferenceBrickAccel() = default;
  std::vector<Triangle> triangles_;    // the usable ones
  std::vector<BvhHitRecord> records_;  // records_[k] belongs to triangles_[k]
  uint32_t triangle_count_ = 0;
  double build_seconds_ = 0;
};

class ReferenceBrickBuilder final : public BrickBuilder {
 public:
  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override;
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return ReferenceBrickAccel::reserve_bytes(triangle_count);
  }
  const std::string& name() const override;
  double hit_rounding_scale() const override { return kWatertightHitRounding; }
};

}  // namespace outcore
