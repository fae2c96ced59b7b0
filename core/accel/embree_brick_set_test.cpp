#include "core/accel/embree_brick_set.h"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <vector>

#include "core/accel/accel_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using namespace accel_test;

std::unique_ptr<EmbreeBrickAccel> build_or_die(BrickData brick, const EmbreeBrickConfig& config = {}) {
  auto accel = EmbreeBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return accel.ok() ? std::move(accel).value() : nullptr;
}

BrickData with_geometry(BrickData brick, uint32_t brick_id, uint32_t geometry_id) {
  brick.brick_id = brick_id;
  for (TriangleId& id : brick.ids) id.geometry_id = geometry_id;
  return brick;
}

bool bitwise_equal(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
}

// Three overlapping bricks, one holding copies of 40 triangles of another
// under larger ids (ties at bitwise equal t across bricks), traced through
// the set and brick by brick in either order: the same hits bitwise (the
// tie rule names the copy with the smaller id), the same occlusion; also
// for coherent rays, which the set traces as streams across bricks.
TEST(EmbreeBrickSet, AnswersBitwiseAsItsBricksTracedOneAfterAnother) {
  for (const EmbreeBrickConfig config :
       {EmbreeBrickConfig{}, EmbreeBrickConfig{true, EmbreeQuality::kMedium}}) {
    SCOPED_TRACE(config.robust ? "robust" : "fast");
    BrickData a = with_geometry(random_triangles(1500, 1), 0, 0);
    BrickData b = with_geometry(random_triangles(1500, 2), 1, 2);
    for (uint32_t k = 0; k < 40; ++k) {
      b.triangles.push_back(a.triangles[k * 7]);
      b.ids.push_back({3, k * 7});
    }
    BrickData c = with_geometry(scattered_triangles(1500, 3), 2, 1);
    Aabb box = bounds_of(a);
    box.extend(bounds_of(b));
    box.extend(bounds_of(c));
    std::vector<std::unique_ptr<EmbreeBrickAccel>> bricks;
    bricks.push_back(build_or_die(std::move(a), config));
    bricks.push_back(build_or_die(std::move(b), config));
    bricks.push_back(build_or_die(std::move(c), config));
    const std::vector<const EmbreeBrickAccel*> pointers = {bricks[0].get(), bricks[1].get(), bricks[2].get()};
    auto set = EmbreeBrickSet::build(pointers);
    ASSERT_TRUE(set.ok()) << set.status().to_string();
    EXPECT_EQ((*set)->bricks(), pointers);
    EXPECT_GT((*set)->memory_bytes(), 0u);

    std::vector<Ray> rays = rays_from_outside(box, 4000, 9);
    // Coherent rays: 16 rows of 256 pixels of a pinhole camera well away
    // from the box (a run of 64 spans about 4 degrees).
    const Vec3f eye = box.center() - Vec3f(0, 0, 3.0f * box.extent().z);
    for (int y = 0; y < 16; ++y) {
      for (int x = 0; x < 256; ++x) {
        Ray r;
        r.origin = eye;
        r.direction = Vec3f(box.lo.x + box.extent().x * (x + 0.5f) / 256,
                            box.lo.y + box.extent().y * (y + 0.5f) / 16, box.center().z) -
                      eye;
        rays.push_back(r);
      }
    }
    std::vector<uint32_t> ids(rays.size());
    for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;

    std::vector<Hit> forward(rays.size()), backward(rays.size()), through_set(rays.size());
    for (const auto& brick : bricks) brick->intersect(ids, rays.data(), forward.data());
    for (auto it = bricks.rbegin(); it != bricks.rend(); ++it)
      (*it)->intersect(ids, rays.data(), backward.data());
    (*set)->intersect(ids, rays.data(), through_set.data());
    EXPECT_TRUE(bitwise_equal(forward, backward)) << "brick order";
    EXPECT_TRUE(bitwise_equal(through_set, forward)) << "set";
    EXPECT_GT((*set)->coherent_rays(), 0u) << "the grid's rays go as streams";
    std::size_t hits = 0, copies_hit = 0;
    for (const Hit& h : through_set) {
      hits += h.is_hit();
      EXPECT_NE(h.geometry_id, 3u) << "a copy under a larger id won a tie";
      copies_hit += h.is_hit() && h.geometry_id == 0 && h.primitive_id % 7 == 0 && h.primitive_id < 280;
    }
    EXPECT_GT(hits, rays.size() / 2);
    EXPECT_GT(copies_hit, 0u) << "the ties should occur";

    std::vector<uint8_t> occluded_bricks(rays.size(), 0), occluded_set(rays.size(), 0);
    for (const auto& brick : bricks) brick->occluded(ids, rays.data(), occluded_bricks.data());
    (*set)->occluded(ids, rays.data(), occluded_set.data());
    EXPECT_EQ(occluded_set, occluded_bricks);
    for (std::size_t i = 0; i < rays.size(); ++i) EXPECT_EQ(occluded_set[i] != 0, forward[i].is_hit()) << i;
  }
}

// A set over one brick with triangles (and one without) traces that brick's
// own scene: no instancing level, no bytes of its own, the brick's answers
// bitwise, ties included.
TEST(EmbreeBrickSet, OneBrickWithTrianglesIsTracedThroughItsOwnScene) {
  BrickData with = with_geometry(random_triangles(2000, 4), 0, 0);
  for (uint32_t k = 0; k < 30; ++k) {
    with.triangles.push_back(with.triangles[k * 5]);
    with.ids.push_back({1, k * 5});
  }
  const Aabb box = bounds_of(with);
  BrickData without;
  without.brick_id = 1;
  for (uint32_t k = 0; k < 4; ++k) {
    const Vec3f p(float(k), 0, 0);
    without.triangles.push_back({p, p, p});
    without.ids.push_back({2, k});
  }
  auto brick = build_or_die(std::move(with));
  auto empty = build_or_die(std::move(without));
  ASSERT_NE(brick, nullptr);
  ASSERT_NE(empty, nullptr);
  const std::vector<const EmbreeBrickAccel*> pointers = {empty.get(), brick.get()};
  auto set = EmbreeBrickSet::build(pointers);
  ASSERT_TRUE(set.ok()) << set.status().to_string();
  EXPECT_EQ((*set)->memory_bytes(), 0u);
  const std::vector<Ray> rays = rays_from_outside(box, 3000, 12);
  std::vector<uint32_t> ids(rays.size());
  for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
  std::vector<Hit> direct(rays.size()), through_set(rays.size());
  brick->intersect(ids, rays.data(), direct.data());
  (*set)->intersect(ids, rays.data(), through_set.data());
  EXPECT_TRUE(bitwise_equal(through_set, direct));
  std::size_t hits = 0;
  for (const Hit& h : through_set) {
    hits += h.is_hit();
    EXPECT_NE(h.geometry_id, 1u) << "a copy under a larger id won a tie";
  }
  EXPECT_GT(hits, rays.size() / 4);
  std::vector<uint8_t> occluded_direct(rays.size(), 0), occluded_set(rays.size(), 0);
  brick->occluded(ids, rays.data(), occluded_direct.data());
  (*set)->occluded(ids, rays.data(), occluded_set.data());
  EXPECT_EQ(occluded_set, occluded_direct);
}

// Bricks without a triangle Embree can hit (all degenerate) give a set
// without a scene: it answers nothing and changes no answer it is given.
TEST(EmbreeBrickSet, BricksWithoutTrianglesGiveASetThatAnswersNothing) {
  BrickData flat;
  for (uint32_t k = 0; k < 10; ++k) {
    const Vec3f p(float(k), 0, 0);
    flat.triangles.push_back({p, p, p + Vec3f(1, 0, 0)});
    flat.ids.push_back({0, k});
  }
  auto brick = build_or_die(std::move(flat));
  ASSERT_NE(brick, nullptr);
  const std::vector<const EmbreeBrickAccel*> pointers = {brick.get()};
  auto set = EmbreeBrickSet::build(pointers);
  ASSERT_TRUE(set.ok()) << set.status().to_string();
  Ray ray;
  ray.origin = {0.5f, 0, -1};
  ray.direction = {0, 0, 1};
  Hit given;
  given.t = 3.0f;
  given.geometry_id = 4;
  given.primitive_id = 9;
  std::vector<Hit> hits = {given};
  const uint32_t id = 0;
  (*set)->intersect({&id, 1}, &ray, hits.data());
  EXPECT_TRUE(bitwise_equal(hits, std::vector<Hit>{given}));
  uint8_t occluded = 0;
  (*set)->occluded({&id, 1}, &ray, &occluded);
  EXPECT_EQ(occluded, 0);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
