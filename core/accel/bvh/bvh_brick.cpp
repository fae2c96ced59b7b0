#include "core/accel/bvh/bvh_brick.h"

#include "core/accel/bvh/wide_bvh_queries.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bvh/bvh_brick_serializer.h"
#include "core/accel/bvh/wide_bvh_collapse.h"
#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore {

Expected<std::unique_ptr<BvhBrickAccel>> BvhBrickAccel::build(BrickData&& brick,
                                                              const BvhBrickConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = brick_build_context(brick, "bvh");
  OUTCORE_RETURN_IF_ERROR(check_brick_build_input(brick, what, kMaxTriangles));
  const Status valid = config.builder.validate();
  if (!valid.ok()) return invalid_argument(what + ": " + valid.message());

  std::unique_ptr<BvhBrickAccel> accel(new BvhBrickAccel());
  accel->test_ = config.triangle_test;
  accel->brick_id_ = brick.brick_id;
  accel->triangle_count_ = static_cast<uint32_t>(n);

  keep_usable_triangles(brick);
  const uint64_t input_bytes = brick.memory_bytes();

  BinnedSahBuilder::Result binary = BinnedSahBuilder::build(brick.triangles, config.builder);
  const uint64_t binary_bytes =
      binary.nodes.capacity() * sizeof(BvhNode) + binary.order.capacity() * sizeof(uint32_t);
  WideBvhCollapser::Result wide =
      WideBvhCollapser::collapse(binary.nodes, binary.order, brick.triangles, brick.ids);
  const uint64_t peak = input_bytes + std::max(binary.peak_bytes, binary_bytes + wide.peak_bytes);
  brick.triangles = {};
  brick.ids = {};

  accel->tree_ = std::move(wide.tree);
  accel->view_ = accel->tree_.view();
  accel->memory_bytes_ = accel->tree_.memory_bytes() + kOverheadBytes;
  accel->build_peak_bytes_ = peak + kOverheadBytes;
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

std::unique_ptr<BvhBrickAccel> BvhBrickAccel::from_tree(WideBvh tree, TriangleTest test, uint32_t brick_id,
                                                        uint32_t triangle_count) {
  std::unique_ptr<BvhBrickAccel> accel(new BvhBrickAccel());
  accel->tree_ = std::move(tree);
  accel->view_ = accel->tree_.view();
  accel->memory_bytes_ = accel->tree_.memory_bytes() + kOverheadBytes;
  accel->test_ = test;
  accel->brick_id_ = brick_id;
  accel->triangle_count_ = triangle_count;
  accel->build_peak_bytes_ = accel->memory_bytes();
  return accel;
}

std::unique_ptr<BvhBrickAccel> BvhBrickAccel::from_view(const WideBvhView& view,
                                                        std::shared_ptr<const void> owner, TriangleTest test,
                                                        uint32_t brick_id, uint32_t triangle_count) {
  std::unique_ptr<BvhBrickAccel> accel(new BvhBrickAccel());
  accel->owner_ = std::move(owner);
  accel->view_ = view;
  // As a build of the same tree reports (its arrays are exactly sized).
  accel->memory_bytes_ = view.nodes.size_bytes() + view.packets.size_bytes() + kOverheadBytes;
  accel->test_ = test;
  accel->brick_id_ = brick_id;
  accel->triangle_count_ = triangle_count;
  accel->build_peak_bytes_ = accel->memory_bytes();
  return accel;
}

// reserve_bytes(n) bounds the build's peak, which is the input brick (44
// B/tri, compacted in place, exact from the store) plus the larger of the
// binary builder's peak and, while collapsing, the binary nodes and order
// (at most 2n - 1 nodes and n indices) plus the collapser's peak (the wide
// tree and its scratch). It also bounds memory_bytes() after the build:
// about 50 B/tri on the bunny with the default config (tested).
uint64_t BvhBrickAccel::reserve_bytes(uint64_t triangle_count) {
  const uint64_t n = triangle_count;
  const uint64_t binary_kept = 2 * n * sizeof(BvhNode) + n * sizeof(uint32_t);
  return kOverheadBytes + n * (sizeof(Triangle) + sizeof(TriangleId)) +
         std::max(BinnedSahBuilder::peak_bytes_bound(n), binary_kept + WideBvhCollapser::peak_bytes_bound(n));
}

void BvhBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  wide_bvh_intersect(active_simd_path(), test_, view_, ray_ids, rays, hits);
}

void BvhBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  wide_bvh_occluded(active_simd_path(), test_, view_, ray_ids, rays, occluded);
}

void BvhBrickAccel::all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                             std::vector<RayHitRecord>& out) const {
  wide_bvh_all_hits(active_simd_path(), test_, view_, ray_ids, rays, out);
}

void BvhBrickAccel::count_hits(std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts) const {
  wide_bvh_count_hits(active_simd_path(), test_, view_, ray_ids, rays, counts);
}

void BvhBrickAccel::closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                                   ClosestPoint* best) const {
  wide_bvh_closest_points(view_, point_ids, points, best);
}

BvhBrickBuilder::BvhBrickBuilder(const BvhBrickConfig& config)
    : config_(config), serializer_(std::make_unique<BvhBrickSerializer>(config)) {}

BvhBrickBuilder::~BvhBrickBuilder() = default;

const BrickSerializer* BvhBrickBuilder::serializer() const {
  return serializer_.get();
}

Expected<std::unique_ptr<BrickAccel>> BvhBrickBuilder::build(BrickData&& brick) const {
  OUTCORE_ASSIGN_OR_RETURN(auto accel, BvhBrickAccel::build(std::move(brick), config_));
  return std::unique_ptr<BrickAccel>(std::move(accel));
}

const std::string& BvhBrickBuilder::name() const {
  static const std::string kName = "bvh";
  return kName;
}

}  // namespace outcore
