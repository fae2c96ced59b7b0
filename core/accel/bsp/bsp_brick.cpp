#include "core/accel/bsp/bsp_brick.h"

#include <chrono>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bsp/bsp_brick_serializer.h"
#include "core/accel/bsp/bsp_tree_traversal.h"
#include "core/accel/bvh/scalar_triangle_test_dispatch.h"

namespace outcore {

Expected<std::unique_ptr<BspBrickAccel>> BspBrickAccel::build(BrickData&& brick,
                                                              const BspBrickConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = brick_build_context(brick, "bsp");
  OUTCORE_RETURN_IF_ERROR(check_brick_build_input(brick, what, kMaxTriangles));
  const Status valid = config.builder.validate();
  if (!valid.ok()) return invalid_argument(what + ": " + valid.message());

  std::unique_ptr<BspBrickAccel> accel(new BspBrickAccel());
  accel->test_ = config.triangle_test;
  accel->triangle_count_ = static_cast<uint32_t>(n);
  accel->brick_id_ = brick.brick_id;
  keep_usable_triangles(brick);
  const uint64_t input_bytes = brick.memory_bytes();
  BspTreeBuilder::Result built = BspTreeBuilder::build(std::move(brick.triangles), brick.ids, config.builder);
  brick.ids = {};
  accel->tree_ = std::move(built.tree);
  accel->build_peak_bytes_ = input_bytes + built.peak_bytes + accel->tree_.memory_bytes() + kOverheadBytes;
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

std::unique_ptr<BspBrickAccel> BspBrickAccel::from_tree(BspTree tree, TriangleTest test, uint32_t brick_id,
                                                        uint32_t triangle_count) {
  std::unique_ptr<BspBrickAccel> accel(new BspBrickAccel());
  accel->tree_ = std::move(tree);
  accel->test_ = test;
  accel->brick_id_ = brick_id;
  accel->triangle_count_ = triangle_count;
  return accel;
}

uint64_t BspBrickAccel::reserve_bytes(uint64_t triangle_count) {
  const uint64_t n = triangle_count;
  return kOverheadBytes + n * (sizeof(Triangle) + sizeof(TriangleId)) + BspTreeBuilder::peak_bytes_bound(n) +
         BspTreeBuilder::tree_bytes_bound(n);
}

void BspBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  const BspTreeView view = tree_.view();
  with_scalar_triangle_test(test_, [&]<class Test>() {
    for (const uint32_t i : ray_ids) bsp_closest_hit<Test>(view, rays[i], hits[i]);
  });
}

void BspBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  const BspTreeView view = tree_.view();
  with_scalar_triangle_test(test_, [&]<class Test>() {
    for (const uint32_t i : ray_ids) {
      if (occluded[i] == 0 && bsp_any_hit<Test>(view, rays[i])) occluded[i] = 1;
    }
  });
}

BspBrickBuilder::BspBrickBuilder(const BspBrickConfig& config)
    : config_(config), serializer_(std::make_unique<BspBrickSerializer>(config)) {}

BspBrickBuilder::~BspBrickBuilder() = default;

const BrickSerializer* BspBrickBuilder::serializer() const {
  return serializer_.get();
}

Expected<std::unique_ptr<BrickAccel>> BspBrickBuilder::build(BrickData&& brick) const {
  OUTCORE_ASSIGN_OR_RETURN(auto accel, BspBrickAccel::build(std::move(brick), config_));
  return std::unique_ptr<BrickAccel>(std::move(accel));
}

const std::string& BspBrickBuilder::name() const {
  static const std::string kName = "bsp";
  return kName;
}

}  // namespace outcore
