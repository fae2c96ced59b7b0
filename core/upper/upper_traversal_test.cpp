#include "core/upper/upper_traversal.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "core/upper/upper_hierarchy_builder.h"
#include "core/upper/upper_wide8_traversal.h"
#include "tests/support/grid_boxes.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// The grid of [-2, 2] (dense overlaps) for the boxes, [-4, 4] for the rays.
std::vector<Aabb> tricky_boxes(std::size_t n, std::mt19937& rng) {
  return testing::grid_boxes(n, rng, 2);
}

Ray tricky_ray(std::mt19937& rng) {
  return testing::grid_ray(rng, 4);
}

// Walks every brick of the ray front to back with window size N, both ways,
// and expects the same windows at every step.
template <std::size_t N>
void expect_same_walk(const UpperHierarchy& upper, const FlatLeaves& flat, const Ray& ray) {
  const SlabRay slab(ray);
  BrickKey after;
  for (int step = 0; step < 64; ++step) {
    std::array<BrickKey, N> a{}, b{};
    uint64_t nodes_a = 0, nodes_b = 0;
    const uint32_t found_a = next_bricks(upper, slab, ray.tnear, ray.tfar, after, a, nodes_a);
    const uint32_t found_b = next_bricks_flat(flat, slab, ray.tnear, ray.tfar, after, b, nodes_b);
    ASSERT_EQ(found_a, found_b);
    for (uint32_t k = 0; k < found_a; ++k) {
      ASSERT_EQ(a[k].brick, b[k].brick) << "key " << k;
      ASSERT_EQ(std::memcmp(&a[k].entry, &b[k].entry, sizeof(float)), 0) << "key " << k;
    }
    if (found_a < N) return;
    after = a[found_a - 1];
  }
  FAIL() << "walk did not end";
}

TEST(UpperTraversal, FlatLeavesFindTheSameBricksAsTheHierarchy) {
  std::mt19937 rng(7);
  for (std::size_t n = 1; n <= FlatLeaves::kMaxLeaves; ++n) {
    for (int scene = 0; scene < 20; ++scene) {
      const auto boxes = tricky_boxes(n, rng);
      const UpperHierarchy upper = build_upper_hierarchy(boxes);
      FlatLeaves flat;
      ASSERT_TRUE(make_flat_leaves(upper, flat));
      ASSERT_EQ(flat.count, n);
      for (int r = 0; r < 200; ++r) {
        const Ray ray = tricky_ray(rng);
        expect_same_walk<4>(upper, flat, ray);
        expect_same_walk<2>(upper, flat, ray);
        if (HasFatalFailure()) return;
      }
    }
  }
}

// The simple reference: every leaf's own slab test, no hierarchy.
template <std::size_t N>
uint32_t reference_next_bricks(const UpperHierarchy& upper, const SlabRay& ray, float tmin, float tmax,
                               const BrickKey& after, std::array<BrickKey, N>& window) {
  uint32_t found = 0;
  for (const UpperNode& node : upper.nodes) {
    float entry;
    if (!node.is_leaf || !detail::slab_test_scalar(ray, node.bounds, tmin, tmax, after.entry, entry))
      continue;
    const BrickKey key{entry, node.child_or_brick};
    if (after < key) detail::insert_key(key, window, found);
  }
  return found;
}

// Front-to-back walks over large hierarchies find, window by window, what
// testing every leaf finds, also when the horizon shrinks under the walk
// (a hit found in a brick): the binary, 4-wide and 8-wide (AVX) walks.
TEST(UpperTraversal, HierarchyFindsWhatTestingEveryLeafFinds) {
  std::mt19937 rng(9);
  for (const std::size_t n : {1, 2, 5, 9, 40, 300}) {
    const auto boxes = tricky_boxes(n, rng);
    const UpperHierarchy upper = build_upper_hierarchy(boxes);
    WideUpper wide;
    make_wide_upper(upper, wide);
    WideUpper8 wide8;
    make_wide_upper(upper, wide8);
    if (n >= 9) {
      EXPECT_LT(wide.nodes.size(), upper.nodes.size() / 2);
      EXPECT_LT(wide8.nodes.size(), wide.nodes.size());
    }
    for (int r = 0; r < 2000; ++r) {
      const Ray ray = tricky_ray(rng);
      const SlabRay slab(ray);
      BrickKey after;
      float tmax = ray.tfar;
      for (int step = 0; step < 400; ++step) {
        std::array<BrickKey, 4> a{}, b{}, c{};
        uint64_t nodes = 0;
        const uint32_t found_a = next_bricks(upper, slab, ray.tnear, tmax, after, a, nodes);
        const uint32_t found_b = reference_next_bricks(upper, slab, ray.tnear, tmax, after, b);
        const uint32_t found_c = next_bricks_wide(wide, slab, ray.tnear, tmax, after, c, nodes);
        ASSERT_EQ(found_a, found_b) << "n " << n << " ray " << r << " step " << step;
        ASSERT_EQ(found_c, found_b) << "wide: n " << n << " ray " << r << " step " << step;
        if (cpu_has_avx()) {
          std::array<BrickKey, 4> d{};
          const uint32_t found_d = next_bricks_wide8(wide8, slab, ray.tnear, tmax, after, d, nodes);
          ASSERT_EQ(found_d, found_b) << "wide8: n " << n << " ray " << r << " step " << step;
          for (uint32_t k = 0; k < found_d; ++k) {
            ASSERT_EQ(d[k].brick, b[k].brick);
            ASSERT_EQ(std::memcmp(&d[k].entry, &b[k].entry, sizeof(float)), 0);
          }
        }
        for (uint32_t k = 0; k < found_a; ++k) {
          ASSERT_EQ(a[k].brick, b[k].brick);
          ASSERT_EQ(std::memcmp(&a[k].entry, &b[k].entry, sizeof(float)), 0);
          ASSERT_EQ(c[k].brick, b[k].brick);
          ASSERT_EQ(std::memcmp(&c[k].entry, &b[k].entry, sizeof(float)), 0);
        }
        if (found_a < 4) break;
        after = a[found_a - 1];
        if (r % 3 == 0 && std::isfinite(a[1].entry)) tmax = std::max(a[1].entry, ray.tnear);  // a hit
      }
    }
  }
}

// A ray running in the plane of a box's face (a zero direction component,
// either sign, the origin on the plane) lies in the closed box: every walk
// reports the box's brick, on the lower face and the upper face alike.
// (Conservative, not exact: a zero direction component constrains nothing
// at all, since the widening turns an infinite distance into NaN, so boxes
// beside the plane are reported too.)
TEST(UpperTraversal, ARayAlongABoxFaceReachesItsBrick) {
  std::vector<Aabb> boxes;
  for (int k = 0; k < 12; ++k) {
    Aabb b;
    b.extend(Vec3f(float(k % 4), float(k / 4), 0.0f));
    b.extend(Vec3f(float(k % 4) + 1, float(k / 4) + 1, 1.0f));
    boxes.push_back(b);
  }
  const UpperHierarchy upper = build_upper_hierarchy(boxes);
  WideUpper wide;
  make_wide_upper(upper, wide);
  WideUpper8 wide8;
  make_wide_upper(upper, wide8);
  FlatLeaves flat;
  std::vector<Aabb> few(boxes.begin(), boxes.begin() + 4);
  const UpperHierarchy small = build_upper_hierarchy(few);
  ASSERT_TRUE(make_flat_leaves(small, flat));
  for (const float y : {0.0f, 1.0f, 2.0f, 3.0f}) {
    for (const float dy : {0.0f, -0.0f}) {
      for (const float dz : {1.0f, -1.0f}) {
        SCOPED_TRACE("y " + std::to_string(y) + " dy " + (std::signbit(dy) ? "-0" : "+0") + " dz " +
                     std::to_string(dz));
        Ray ray;
        ray.origin = Vec3f(1.5f, y, dz > 0 ? -1.0f : 2.0f);
        ray.direction = Vec3f(0.0f, dy, dz);
        const SlabRay slab(ray);
        // The boxes x in [1, 2] with y on one of their faces.
        std::vector<uint32_t> expected;
        for (uint32_t k = 0; k < boxes.size(); ++k)
          if (boxes[k].lo.x == 1.0f && boxes[k].lo.y <= y && y <= boxes[k].hi.y) expected.push_back(k);
        ASSERT_FALSE(expected.empty());
        // The expected bricks among those found (a window of 16 holds all 12).
        const auto found_bricks = [&](const std::array<BrickKey, 16>& window, uint32_t found) {
          EXPECT_LT(found, 16u) << "window full: the check would be incomplete";
          std::vector<uint32_t> bricks;
          for (uint32_t k = 0; k < found; ++k) bricks.push_back(window[k].brick);
          std::vector<uint32_t> kept;
          for (const uint32_t b : expected)
            if (std::find(bricks.begin(), bricks.end(), b) != bricks.end()) kept.push_back(b);
          return kept;
        };
        std::array<BrickKey, 16> window{};
        uint64_t nodes = 0;
        uint32_t found = next_bricks(upper, slab, ray.tnear, ray.tfar, BrickKey{}, window, nodes);
        EXPECT_EQ(found_bricks(window, found), expected) << "binary";
        found = next_bricks_wide(wide, slab, ray.tnear, ray.tfar, BrickKey{}, window, nodes);
        EXPECT_EQ(found_bricks(window, found), expected) << "4-wide";
        if (cpu_has_avx()) {
          found = next_bricks_wide8(wide8, slab, ray.tnear, ray.tfar, BrickKey{}, window, nodes);
          EXPECT_EQ(found_bricks(window, found), expected) << "8-wide";
        }
        if (y <= 1.0f) {
          found = next_bricks_flat(flat, slab, ray.tnear, ray.tfar, BrickKey{}, window, nodes);
          std::vector<uint32_t> flat_expected;
          for (const uint32_t k : expected)
            if (k < 4) flat_expected.push_back(k);
          std::vector<uint32_t> flat_found;
          for (uint32_t k = 0; k < found; ++k) flat_found.push_back(window[k].brick);
          for (const uint32_t k : flat_expected)
            EXPECT_NE(std::find(flat_found.begin(), flat_found.end(), k), flat_found.end()) << "flat " << k;
        }
      }
    }
  }
}

// The SSE slab test against the scalar one: same verdict, bitwise same entry
// (signed zeros included), over boxes with flat sides and points, rays on slab
// planes and with zero direction components, and infinite or tiny segments.
TEST(UpperTraversal, SseSlabTestIsBitwiseTheScalarOne) {
  std::mt19937 rng(10);
  std::uniform_real_distribution<float> u(0.0f, 3.0f);
  for (int scene = 0; scene < 200; ++scene) {
    const auto boxes = tricky_boxes(8, rng);
    std::vector<UpperNode> nodes(boxes.size());
    for (std::size_t k = 0; k < boxes.size(); ++k) nodes[k].bounds = boxes[k], nodes[k].child_or_brick = 5;
    for (int r = 0; r < 200; ++r) {
      const Ray ray = tricky_ray(rng);
      const SlabRay slab(ray);
      const float tmax = r % 4 == 0 ? std::numeric_limits<float>::infinity() : ray.tnear + u(rng);
      const float min_exit = r % 5 == 0 ? -std::numeric_limits<float>::infinity() : u(rng);
      for (const UpperNode& node : nodes) {
        float a = -1, b = -1;
        const bool hit_a = detail::slab_test(slab, node.bounds, ray.tnear, tmax, min_exit, a);
        const bool hit_b = detail::slab_test_scalar(slab, node.bounds, ray.tnear, tmax, min_exit, b);
        ASSERT_EQ(hit_a, hit_b);
        ASSERT_EQ(std::memcmp(&a, &b, sizeof(float)), 0) << a << " vs " << b;
      }
    }
  }
}

TEST(UpperTraversal, LargerHierarchiesAreNotFlattened) {
  std::mt19937 rng(8);
  const auto boxes = tricky_boxes(FlatLeaves::kMaxLeaves + 1, rng);
  FlatLeaves flat;
  EXPECT_FALSE(make_flat_leaves(build_upper_hierarchy(boxes), flat));
  EXPECT_FALSE(make_flat_leaves(UpperHierarchy{}, flat));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
