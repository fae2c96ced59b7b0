#include "core/io/vertex_spill.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "core/io/reader_test_util.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;

struct RandomMesh {
  std::vector<Vec3f> vertices;
  std::vector<uint64_t> corners;  // 3 per triangle
};

RandomMesh random_mesh(uint64_t vertex_count, uint64_t triangle_count, uint32_t seed) {
  RandomMesh mesh;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coordinate(-100.0f, 100.0f);
  std::uniform_int_distribution<uint64_t> index(0, vertex_count - 1);
  for (uint64_t v = 0; v < vertex_count; ++v)
    mesh.vertices.emplace_back(coordinate(rng), coordinate(rng), -0.0f);
  for (uint64_t c = 0; c < 3 * triangle_count; ++c) mesh.corners.push_back(index(rng));
  return mesh;
}

std::vector<Triangle> expected_triangles(const RandomMesh& mesh) {
  std::vector<Triangle> triangles;
  for (std::size_t c = 0; c < mesh.corners.size(); c += 3) {
    triangles.push_back({mesh.vertices[mesh.corners[c]], mesh.vertices[mesh.corners[c + 1]],
                         mesh.vertices[mesh.corners[c + 2]]});
  }
  return triangles;
}

Expected<std::unique_ptr<SpilledTriangles>> spill(const RandomMesh& mesh, uint64_t allowance,
                                                  const std::string& dir) {
  SpillingFaceResolver spilling("mesh.obj", allowance, dir);
  OUTCORE_RETURN_IF_ERROR(spilling.begin());
  for (const Vec3f& v : mesh.vertices) OUTCORE_RETURN_IF_ERROR(spilling.add_vertex(v));
  for (std::size_t c = 0; c < mesh.corners.size(); c += 3) {
    OUTCORE_RETURN_IF_ERROR(spilling.add_triangle(mesh.corners[c], mesh.corners[c + 1], mesh.corners[c + 2]));
  }
  return spilling.finish();
}

Expected<std::vector<Triangle>> stream_spilled(const SpilledTriangles& spilled) {
  std::vector<Triangle> triangles;
  CallbackSink sink([&](std::span<const Triangle> batch) {
    EXPECT_LE(batch.size(), TriangleBatcher::kBatchSize);
    triangles.insert(triangles.end(), batch.begin(), batch.end());
    return Status::Ok();
  });
  OUTCORE_RETURN_IF_ERROR(spilled.stream(sink));
  return triangles;
}

// From one run sorted in memory to hundreds merged two at a time.
TEST(SpillingFaceResolver, ResolvesRandomIndicesLikeTheInMemoryMeshAtEveryAllowance) {
  const RandomMesh mesh = random_mesh(20000, 30000, 7);
  const std::vector<Triangle> expected = expected_triangles(mesh);
  for (const uint64_t allowance : {uint64_t{1}, uint64_t{64} << 10, uint64_t{1} << 20, uint64_t{64} << 20}) {
    SCOPED_TRACE("allowance " + std::to_string(allowance));
    TempDir dir;
    auto spilled = spill(mesh, allowance, dir.path());
    ASSERT_TRUE(spilled.ok()) << spilled.status().to_string();
    EXPECT_EQ((*spilled)->triangle_count(), expected.size());
    for (int pass = 0; pass < 2; ++pass) {
      auto triangles = stream_spilled(**spilled);
      ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
      EXPECT_TRUE(testing::same_bits(*triangles, expected));
    }
    EXPECT_FALSE(std::filesystem::is_empty(dir.path())) << "the triangle file lives as long as its owner";
    spilled = internal_error("dropped");
    EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << "temporary files left behind";
  }
}

TEST(SpillingFaceResolver, MeshWithoutTrianglesStreamsNothing) {
  TempDir dir;
  auto spilled = spill(random_mesh(10, 0, 1), 1, dir.path());
  ASSERT_TRUE(spilled.ok()) << spilled.status().to_string();
  auto triangles = stream_spilled(**spilled);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  EXPECT_TRUE(triangles->empty());
}

TEST(SpillingFaceResolver, AbandonedMeshRemovesItsFiles) {
  TempDir dir;
  {
    SpillingFaceResolver spilling("mesh.obj", 1, dir.path());
    ASSERT_TRUE(spilling.begin().ok());
    for (uint32_t v = 0; v < 5000; ++v) ASSERT_TRUE(spilling.add_vertex(Vec3f(1, 2, 3)).ok());
    for (uint32_t t = 0; t < 5000; ++t) ASSERT_TRUE(spilling.add_triangle(t, 0, 4999 - t).ok());
    EXPECT_FALSE(std::filesystem::is_empty(dir.path()));
  }  // e.g. the reader found a parse error
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(SpillingFaceResolver, MissingTemporaryDirectoryFailsNamingIt) {
  TempDir dir;
  SpillingFaceResolver spilling("mesh.obj", 1, dir.file("missing"));
  const Status status = spilling.begin();
  EXPECT_EQ(status.code(), StatusCode::kNotFound);
  EXPECT_TRUE(testing::contains(status.message(), dir.file("missing"))) << status.message();
}

TEST(SpillingFaceResolver, PlanStaysWithinTheAllowance) {
  for (const uint64_t mib : {1, 4, 8, 128, 1024}) {
    SCOPED_TRACE(std::to_string(mib) + " MiB");
    const uint64_t allowance = mib << 20;
    const auto plan = SpillingFaceResolver::Plan::for_allowance(allowance);
    EXPECT_GE(plan.fan_in, 2u);
    EXPECT_LE(plan.fan_in, 64u);
    // A merge's buffers plus the sort run being filled plus two streams.
    EXPECT_LE(plan.run_bytes + plan.fan_in * plan.merge_bytes + 2 * plan.stream_bytes, allowance);
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
