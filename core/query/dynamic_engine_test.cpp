// The engine with a dynamic layer: a batch traces the static store, then the
// version of the layer it names, and keeps the nearer hit under the one tie
// rule — checked against float64 brute force over the static triangles and
// the instances' world triangles together; ids continue after the store's
// inputs; a named old version is answered as it was; invalid rays stay
// misses; the statistics say what the layer did.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "core/accel/brute_force_reference.h"
#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// An axis-aligned box as 8 vertices and 12 triangles (closed).
constexpr float kBoxVertices[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
constexpr uint32_t kBoxTriangles[] = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                      2, 3, 7, 2, 7, 6, 1, 2, 6, 1, 6, 5, 0, 4, 7, 0, 7, 3};

std::vector<double> scaled_at(double scale, Vec3d at) {
  return {scale, 0, 0, at.x, 0, scale, 0, at.y, 0, 0, scale, at.z};
}

struct Reference {
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;
};

Reference with_dynamic(const testing::PackedScene& scene, const DynamicSnapshot& dynamic) {
  Reference r{scene.triangles, scene.ids};
  for (const DynamicInstance& instance : dynamic.instances) {
    const DynamicMesh& mesh = *dynamic.meshes[instance.mesh_id];
    for (uint32_t t = 0; t < mesh.triangle_count(); ++t) {
      const auto& tri = mesh.topology()->triangles[t];
      const auto place = [&](uint32_t k) {
        return Vec3f(instance.to_world.point(Vec3d(mesh.vertices()[k])));
      };
      r.triangles.push_back({place(tri[0]), place(tri[1]), place(tri[2])});
      r.ids.push_back({instance.geometry_id, t});
    }
  }
  return r;
}

class DynamicEngine : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    bunny_ = testing::pack_test_scene({testing::model_path("stanford-bunny.obj")}, 8192).release();
  }
  static void TearDownTestSuite() { delete bunny_; }
  static testing::PackedScene* bunny_;
};
testing::PackedScene* DynamicEngine::bunny_ = nullptr;

TEST_F(DynamicEngine, BatchesAnswerAsBruteForceOverStaticAndDynamicTogether) {
  EngineOptions options;
  options.cache_bytes = uint64_t{1} << 30;
  auto engine = QueryEngine::open(bunny_->path, options);
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  DynamicScene& dynamic = (*engine)->dynamic();
  const auto box = dynamic.add_mesh(kBoxVertices, kBoxTriangles);
  ASSERT_TRUE(box.ok()) << box.status().to_string();
  const Aabb b = bunny_->bounds;
  const Vec3f e = b.extent();
  // One box through the bunny, one beside it.
  const auto inside = dynamic.add_instance(box->id, scaled_at(0.4 * e.x, Vec3d(b.center()) - Vec3d(e) * 0.2));
  const auto beside =
      dynamic.add_instance(box->id, scaled_at(0.3 * e.x, Vec3d(b.hi) + Vec3d(0, -0.5 * e.y, 0)));
  ASSERT_TRUE(inside.ok() && beside.ok());
  EXPECT_EQ(inside->id, 1u) << "dynamic ids continue after the store's one input";
  EXPECT_EQ(beside->id, 2u);

  Aabb all = b;
  for (const auto& i : dynamic.latest()->instances) all.extend(i.world_box);
  std::vector<Ray> rays = testing::make_test_rays(all, 1000, 11);
  rays[5].direction = {0, 0, 0};  // invalid: a miss, never a dynamic hit
  std::vector<Hit> hits(rays.size());
  QueryStats stats;
  ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
  const Reference ref = with_dynamic(*bunny_, *dynamic.latest());
  std::size_t dynamic_hits = 0, static_hits = 0, disagreements = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (i == 5) {
      EXPECT_FALSE(hits[i].is_hit());
      continue;
    }
    const ReferenceHit want = reference_closest_hit(ref.triangles, ref.ids, rays[i]);
    if (want.is_hit() != hits[i].is_hit() ||
        (want.is_hit() && std::fabs(hits[i].t - want.t) > 1e-5 * std::max(1.0, want.t))) {
      ++disagreements;
      continue;
    }
    if (!want.is_hit()) continue;
    (hits[i].geometry_id >= 1 ? dynamic_hits : static_hits) += 1;
    if (want.primitive_id == hits[i].primitive_id) {
      EXPECT_EQ(want.geometry_id, hits[i].geometry_id) << "ray " << i;
    }
  }
  EXPECT_LE(disagreements, 3u) << "only grazing rays may differ from float64";
  EXPECT_GT(dynamic_hits, 30u);
  EXPECT_GT(static_hits, 30u);
  EXPECT_EQ(stats.dynamic_version, dynamic.latest()->version);
  EXPECT_EQ(stats.dynamic_instances, 2u);
  EXPECT_GT(stats.rays_hit_only_dynamic, 0u);
  uint64_t hit_count = 0;
  for (const Hit& h : hits) hit_count += h.is_hit();
  EXPECT_EQ(stats.rays_hit, hit_count);

  std::vector<uint8_t> occluded(rays.size());
  ASSERT_TRUE((*engine)->occluded(rays, occluded, {}).ok());
  for (std::size_t i = 0; i < rays.size(); ++i) EXPECT_EQ(occluded[i] != 0, hits[i].is_hit()) << "ray " << i;
}

TEST_F(DynamicEngine, ABatchNamingAnOldVersionIsAnsweredAsItWas) {
  EngineOptions options;
  options.cache_bytes = uint64_t{1} << 30;
  auto engine = QueryEngine::open(bunny_->path, options);
  ASSERT_TRUE(engine.ok());
  DynamicScene& dynamic = (*engine)->dynamic();
  const uint32_t box = dynamic.add_mesh(kBoxVertices, kBoxTriangles)->id;
  const Aabb b = bunny_->bounds;
  const uint32_t id = dynamic.add_instance(box, scaled_at(0.5 * b.extent().x, Vec3d(b.lo)))->id;
  const uint64_t then = dynamic.latest()->version;
  const std::vector<Ray> rays = testing::make_test_rays(b, 2000, 12);
  std::vector<Hit> before(rays.size()), after(rays.size()), named(rays.size());
  ASSERT_TRUE((*engine)->intersect(rays, before, {}).ok());
  const auto moved =
      dynamic.update_transforms({&id, 1}, scaled_at(0.5 * b.extent().x, Vec3d(b.lo) - Vec3d(5, 5, 5)));
  ASSERT_TRUE(moved.ok());
  ASSERT_TRUE((*engine)->intersect(rays, after, {}).ok());
  EXPECT_NE(std::memcmp(before.data(), after.data(), before.size() * sizeof(Hit)), 0);
  QueryOptions old;
  old.dynamic_version = then;
  QueryStats stats;
  ASSERT_TRUE((*engine)->intersect(rays, named, old, &stats).ok());
  EXPECT_EQ(std::memcmp(before.data(), named.data(), before.size() * sizeof(Hit)), 0);
  EXPECT_EQ(stats.dynamic_version, then);
  old.dynamic_version = *moved + 5;
  const Status future = (*engine)->intersect(rays, named, old);
  EXPECT_EQ(future.code(), StatusCode::kNotFound) << future.to_string();
  // Removing the instance gives the static answers back.
  ASSERT_TRUE(dynamic.remove(id).ok());
  std::vector<Hit> removed(rays.size()), alone(rays.size());
  ASSERT_TRUE((*engine)->intersect(rays, removed, {}).ok());
  auto fresh = QueryEngine::open(bunny_->path, options);
  ASSERT_TRUE((*fresh)->intersect(rays, alone, {}).ok());
  EXPECT_EQ(std::memcmp(removed.data(), alone.data(), removed.size() * sizeof(Hit)), 0);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
