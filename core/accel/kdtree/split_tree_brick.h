// SplitTreeBrickAccel<Traits> / SplitTreeBrickBuilder<Traits>: a brick's
// triangles in a split-plane tree (the kd-tree, kd_tree_brick.h, or the
// restricted BSP, bsp/bsp_brick.h) traced by the trees' shared front-to-back
// stack walk with the triangle test chosen by name. One class for both: the
// trees differ only in their nodes, builder and planes, which Traits names.
//
// Hits follow the bvh brick's contract (bvh_brick.h): tnear < t <= tfar, the
// user's ids, Embree's barycentrics, the float64 normal rounded, ties to the
// smaller (geometry_id, primitive_id); degenerate or non-finite triangles are
// left out. Each tree's serialiser (split_tree_serializer.h) keeps its bricks
// in the subtree tier.
//
// Memory: memory_bytes() = the tree's arrays (8 B per node, 16 for the quadtree, 4 B per
// reference, 56 B per triangle) + kOverheadBytes; reserve_bytes(n) bounds it
// and the build's peak (each builder caps references per triangle).
//
// Traits: kName; Builder (Config with validate(), Result {tree,
// peak_bytes}, build(), peak_bytes_bound(), tree_bytes_bound(),
// kMaxTriangles); Tree; make_serializer(config). The member functions are
// defined in split_tree_brick_impl.h and instantiated once per tree in its
// brick's .cpp, next to its traversal.
//
// Thread-safety: build() may run on many threads at once; a built accel is
// immutable and intersect() / occluded() may run concurrently.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/accel/brick_accel_factory.h"
#include "core/accel/brick_serializer.h"
#include "core/accel/bvh/scalar_triangle_test_dispatch.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/geometry/hit_rounding.h"
#include "core/store/brick_data.h"

namespace outcore {

template <class BuilderConfig>
struct SplitTreeBrickConfig {
  TriangleTest triangle_test = TriangleTest::kWatertight;
  BuilderConfig builder;
};

template <class Traits>
class SplitTreeBrickAccel final : public BrickAccel {
 public:
  using Builder = typename Traits::Builder;
  using Tree = typename Traits::Tree;
  using Config = SplitTreeBrickConfig<typename Builder::Config>;

  static constexpr uint64_t kMaxTriangles = Builder::kMaxTriangles;
  static constexpr uint64_t kOverheadBytes = 8192;

  // Consumes the brick. INVALID_ARGUMENT when ids and triangles differ in
  // count or the config is invalid, OUT_OF_RANGE beyond kMaxTriangles.
  static Expected<std::unique_ptr<SplitTreeBrickAccel>> build(BrickData&& brick, const Config& config);
  // A brick from a tree it owns; the tree must be valid (validate()).
  // triangle_count: the source brick's, degenerate triangles included.
  static std::unique_ptr<SplitTreeBrickAccel> from_tree(Tree tree, TriangleTest test, uint32_t brick_id,
                                                        uint32_t triangle_count);
  static uint64_t reserve_bytes(uint64_t triangle_count);

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;
  // Every hit and closest points scan the brick's triangles (exact; the
  // trees' walks stop at a ray's first hit and know no point distance).
  void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                std::vector<RayHitRecord>& out) const override {
    const auto view = tree_.view();
    with_scalar_triangle_test(test_, [&]<class Test>() {
      all_hits_by_scan<Test>(view.triangles, view.records, ray_ids, rays, out);
    });
  }
  void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                      ClosestPoint* best) const override {
    const auto view = tree_.view();
    closest_points_by_scan(view.triangles, view.records, point_ids, points, best);
  }

  uint64_t memory_bytes() const override { return tree_.memory_bytes() + kOverheadBytes; }
  double build_seconds() const override { return build_seconds_; }
  uint32_t triangle_count() const override { return triangle_count_; }

  // Beyond BrickAccel (statistics and tests):
  auto view() const { return tree_.view(); }
  uint64_t build_peak_bytes() const { return build_peak_bytes_; }
  TriangleTest triangle_test() const { return test_; }
  uint32_t brick_id() const { return brick_id_; }

 private:
  SplitTreeBrickAccel() = default;

  Tree tree_;
  TriangleTest test_ = TriangleTest::kWatertight;
  uint32_t triangle_count_ = 0;  // including the degenerate ones left out
  uint32_t brick_id_ = 0;
  uint64_t build_peak_bytes_ = 0;
  double build_seconds_ = 0;
};

template <class Traits>
class SplitTreeBrickBuilder final : public BrickBuilder {
 public:
  using Accel = SplitTreeBrickAccel<Traits>;
  using Config = typename Accel::Config;

  explicit SplitTreeBrickBuilder(const Config& config)
      : config_(config), serializer_(Traits::make_serializer(config)) {}

  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override {
    OUTCORE_ASSIGN_OR_RETURN(auto accel, Accel::build(std::move(brick), config_));
    return std::unique_ptr<BrickAccel>(std::move(accel));
  }
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return Accel::reserve_bytes(triangle_count);
  }
  const std::string& name() const override {
    static const std::string kName = Traits::kName;
    return kName;
  }
  const BrickSerializer* serializer() const override { return serializer_.get(); }
  double hit_rounding_scale() const override {
    return config_.triangle_test == TriangleTest::kMt ? kMollerTrumboreHitRounding : kWatertightHitRounding;
  }
  const Config& config() const { return config_; }

 private:
  Config config_;
  std::unique_ptr<const BrickSerializer> serializer_;
};

}  // namespace outcore
