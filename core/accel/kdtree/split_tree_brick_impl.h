// The member functions of SplitTreeBrickAccel<Traits> (split_tree_brick.h),
// included by each tree's brick .cpp with its traversal, which provides
// Traits::closest_hit<Test>() and Traits::any_hit<Test>(), and instantiated
// there once.
//
// Thread-safety: as split_tree_brick.h.
#pragma once

#include <chrono>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bvh/scalar_triangle_test_dispatch.h"
#include "core/accel/kdtree/split_tree_brick.h"

namespace outcore {

template <class Traits>
Expected<std::unique_ptr<SplitTreeBrickAccel<Traits>>> SplitTreeBrickAccel<Traits>::build(
    BrickData&& brick, const Config& config) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = brick_build_context(brick, Traits::kName);
  OUTCORE_RETURN_IF_ERROR(check_brick_build_input(brick, what, kMaxTriangles));
  const Status valid = config.builder.validate();
  if (!valid.ok()) return invalid_argument(what + ": " + valid.message());

  std::unique_ptr<SplitTreeBrickAccel> accel(new SplitTreeBrickAccel());
  accel->test_ = config.triangle_test;
  accel->triangle_count_ = static_cast<uint32_t>(n);
  accel->brick_id_ = brick.brick_id;
  keep_usable_triangles(brick);
  const uint64_t input_bytes = brick.memory_bytes();
  typename Builder::Result built = Builder::build(std::move(brick.triangles), brick.ids, config.builder);
  brick.ids = {};
  accel->tree_ = std::move(built.tree);
  accel->build_peak_bytes_ = input_bytes + built.peak_bytes + accel->tree_.memory_bytes() + kOverheadBytes;
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

template <class Traits>
std::unique_ptr<SplitTreeBrickAccel<Traits>> SplitTreeBrickAccel<Traits>::from_tree(Tree tree,
                                                                                    TriangleTest test,
                                                                                    uint32_t brick_id,
                                                                                    uint32_t triangle_count) {
  std::unique_ptr<SplitTreeBrickAccel> accel(new SplitTreeBrickAccel());
  accel->tree_ = std::move(tree);
  accel->test_ = test;
  accel->brick_id_ = brick_id;
  accel->triangle_count_ = triangle_count;
  return accel;
}

template <class Traits>
uint64_t SplitTreeBrickAccel<Traits>::reserve_bytes(uint64_t triangle_count) {
  const uint64_t n = triangle_count;
  return kOverheadBytes + n * (sizeof(Triangle) + sizeof(TriangleId)) + Builder::peak_bytes_bound(n) +
         Builder::tree_bytes_bound(n);
}

template <class Traits>
void SplitTreeBrickAccel<Traits>::intersect(std::span<const uint32_t> ray_ids, const Ray* rays,
                                            Hit* hits) const {
  const auto view = tree_.view();
  with_scalar_triangle_test(test_, [&]<class Test>() {
    for (const uint32_t i : ray_ids) Traits::template closest_hit<Test>(view, rays[i], hits[i]);
  });
}

template <class Traits>
void SplitTreeBrickAccel<Traits>::occluded(std::span<const uint32_t> ray_ids, const Ray* rays,
                                           uint8_t* occluded) const {
  const auto view = tree_.view();
  with_scalar_triangle_test(test_, [&]<class Test>() {
    for (const uint32_t i : ray_ids) {
      if (occluded[i] == 0 && Traits::template any_hit<Test>(view, rays[i])) occluded[i] = 1;
    }
  });
}

}  // namespace outcore
