#include "core/accel/bvh/bvh_brick.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bvh/bvh_brick_serializer.h"
#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"

namespace outcore {
namespace {

Vec3f unit_normal(const Triangle& tri) {
  const Vec3d v0(tri.v0), v1(tri.v1), v2(tri.v2);
  return Vec3f(normalize(cross(v1 - v0, v2 - v0)));
}

// Reorders a and b in place so that new position j holds old position
// order[j], following the permutation's cycles (no second copy of the
// arrays); order is consumed.
template <class A, class B>
void permute_in_place(std::vector<uint32_t>& order, std::vector<A>& a, std::vector<B>& b) {
  for (uint32_t start = 0; start < order.size(); ++start) {
    if (order[start] == start) continue;
    const A held_a = a[start];
    const B held_b = b[start];
    uint32_t j = start;
    while (true) {
      const uint32_t from = order[j];
      order[j] = j;
      if (from == start) {
        a[j] = held_a;
        b[j] = held_b;
        break;
      }
      a[j] = a[from];
      b[j] = b[from];
      j = from;
    }
  }
}

template <class Test>
void intersect_all(const BvhTreeView& tree, std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) {
  for (const uint32_t i : ray_ids) bvh_closest_hit<Test>(tree, rays[i], hits[i]);
}

template <class Test>
void occluded_all(const BvhTreeView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
                  uint8_t* occluded) {
  for (const uint32_t i : ray_ids) {
    if (occluded[i] == 0 && bvh_any_hit<Test>(tree, rays[i])) occluded[i] = 1;
  }
}

}  // namespace

std::string_view triangle_test_name(TriangleTest test) {
  switch (test) {
    case TriangleTest::kMt: return MtTriangleTest::kName;
    case TriangleTest::kWatertight: return WatertightTriangleTest::kName;
    case TriangleTest::kDouble: return DoubleTriangleTest::kName;
  }
  return "?";
}

std::optional<TriangleTest> triangle_test_from_name(std::string_view name) {
  for (const TriangleTest test : kAllTriangleTests) {
    if (name == triangle_test_name(test)) return test;
  }
  return std::nullopt;
}

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
  BvhTree& tree = accel->tree_;

  // The triangles that can be hit, with their hit records, in input order.
  const auto usable = [](const Triangle& tri) { return tri.is_finite() && !tri.is_degenerate(); };
  const uint64_t kept = std::count_if(brick.triangles.begin(), brick.triangles.end(), usable);
  tree.triangles.reserve(kept);
  tree.records.reserve(kept);
  for (uint64_t k = 0; k < n; ++k) {
    const Triangle& tri = brick.triangles[k];
    if (!usable(tri)) continue;
    tree.triangles.push_back(tri);
    tree.records.push_back({unit_normal(tri), brick.ids[k].geometry_id, brick.ids[k].primitive_id});
  }
  uint64_t peak = brick.memory_bytes() + tree.memory_bytes();
  brick.triangles = {};
  brick.ids = {};

  BinnedSahBuilder::Result built = BinnedSahBuilder::build(tree.triangles, config.builder);
  peak = std::max(peak, tree.memory_bytes() + built.peak_bytes);
  tree.nodes = std::move(built.nodes);
  permute_in_place(built.order, tree.triangles, tree.records);
  accel->view_ = tree.view();
  accel->memory_bytes_ = tree.memory_bytes() + kOverheadBytes;
  accel->build_peak_bytes_ = peak + kOverheadBytes;
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

std::unique_ptr<BvhBrickAccel> BvhBrickAccel::from_tree(BvhTree tree, TriangleTest test, uint32_t brick_id,
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

std::unique_ptr<BvhBrickAccel> BvhBrickAccel::from_view(const BvhTreeView& view,
                                                        std::shared_ptr<const void> owner, TriangleTest test,
                                                        uint32_t brick_id, uint32_t triangle_count) {
  std::unique_ptr<BvhBrickAccel> accel(new BvhBrickAccel());
  accel->owner_ = std::move(owner);
  accel->view_ = view;
  // As a build of the same tree reports (its arrays are exactly sized).
  accel->memory_bytes_ =
      view.nodes.size_bytes() + view.triangles.size_bytes() + view.records.size_bytes() + kOverheadBytes;
  accel->test_ = test;
  accel->brick_id_ = brick_id;
  accel->triangle_count_ = triangle_count;
  accel->build_peak_bytes_ = accel->memory_bytes();
  return accel;
}

// reserve_bytes(n) = the builder's scratch + kOverheadBytes + 200 n. The
// peak is the larger of (a) the input brick (44 B/tri) plus the tree's
// triangles and records (56 B/tri), and (b) those 56 B/tri plus the builder's
// peak: centroids and order (16 B/tri) and nodes reserved for a full binary
// tree, then copied to their exact size (at most 2 x 64 B/tri). So (b) <=
// 200 B/tri always, and (a) too while the brick's vectors hold no more than
// about 3 times their size in spare capacity (the store loads them exact).
// After the build, memory_bytes() is 56 B/tri plus 32 B per node: about 92
// B/tri on the bunny with the default config (tested).
uint64_t BvhBrickAccel::reserve_bytes(uint64_t triangle_count) {
  return BinnedSahBuilder::peak_bytes_bound(0) + kOverheadBytes +
         triangle_count * (sizeof(Triangle) + sizeof(BvhHitRecord) + sizeof(Vec3f) + sizeof(uint32_t) +
                           4 * sizeof(BvhNode));
}

void BvhBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  if (view_.nodes.empty()) return;
  switch (test_) {
    case TriangleTest::kMt: return intersect_all<MtTriangleTest>(view_, ray_ids, rays, hits);
    case TriangleTest::kWatertight: return intersect_all<WatertightTriangleTest>(view_, ray_ids, rays, hits);
    case TriangleTest::kDouble: return intersect_all<DoubleTriangleTest>(view_, ray_ids, rays, hits);
  }
}

void BvhBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  if (view_.nodes.empty()) return;
  switch (test_) {
    case TriangleTest::kMt: return occluded_all<MtTriangleTest>(view_, ray_ids, rays, occluded);
    case TriangleTest::kWatertight:
      return occluded_all<WatertightTriangleTest>(view_, ray_ids, rays, occluded);
    case TriangleTest::kDouble: return occluded_all<DoubleTriangleTest>(view_, ray_ids, rays, occluded);
  }
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
