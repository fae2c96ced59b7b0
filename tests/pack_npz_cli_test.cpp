// End-to-end tests of .npz mesh inputs through the real binary: `outcore
// pack` takes an .npz beside other inputs, `outcore trace` answers with the
// input's position and the triangle's row as ids, and a bad archive or one
// too large for --mem-mb fails naming the file (member and row) and leaves
// nothing behind.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "core/io/npz_test_util.h"
#include "core/store/scene_store.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::npy_image;
using testing::raw_bytes;
using testing::SubprocessResult;
using testing::TempDir;
using testing::write_text_file;
using testing::zip_of;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(300'000));
}

void write_npz_mesh(const std::string& path, const std::vector<float>& vertices,
                    const std::vector<int64_t>& triangles, bool deflate = false) {
  const std::string v =
      npy_image("<f4", "(" + std::to_string(vertices.size() / 3) + ", 3)", raw_bytes(vertices));
  const std::string t =
      npy_image("<i8", "(" + std::to_string(triangles.size() / 3) + ", 3)", raw_bytes(triangles));
  write_text_file(path, zip_of({{"vertices.npy", v, deflate}, {"triangles.npy", t, deflate}}));
}

// Rows 0 and 1: a unit square at z = 1; row 2 a degenerate triangle; row 3
// a triangle at z = 3 over x in [2, 3].
const std::vector<float> kVertices = {0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1, 2, 0, 3, 3, 0, 3, 2, 1, 3};
const std::vector<int64_t> kTriangles = {0, 1, 2, 0, 2, 3, 1, 1, 2, 4, 5, 6};

TEST(PackCliNpz, AnNpzInputIsTracedWithItsPositionAndTriangleRowsAsIds) {
  TempDir dir;
  const std::string npz = dir.file("mesh.npz");
  write_npz_mesh(npz, kVertices, kTriangles);
  // Input 1: an OBJ triangle at z = 2 over x in [4, 5].
  const std::string obj = dir.file("tri.obj");
  write_text_file(obj, "v 4 0 2\nv 5 0 2\nv 4 1 2\nf 1 2 3\n");
  const std::string store = dir.file("scene");
  const SubprocessResult packed = outcore({"pack", npz, obj, "-o", store, "-q", "--no-sync"});
  ASSERT_TRUE(packed.succeeded()) << packed.describe();

  auto opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok()) << opened.status().to_string();
  const auto& inputs = (*opened)->manifest().inputs;
  ASSERT_EQ(inputs.size(), 2u);
  EXPECT_EQ(inputs[0].spec, npz);
  EXPECT_EQ(inputs[0].triangle_count, 4u);
  EXPECT_EQ(inputs[0].degenerate_count, 1u);

  // Straight down (-z) from z = 10 onto: the square's two halves, the z = 3
  // triangle, the OBJ triangle, and nothing.
  struct Aim {
    float x, y;
    uint32_t geometry_id, primitive_id;
    float z;
  };
  const std::vector<Aim> aims = {{0.75f, 0.25f, 0, 0, 1},
                                 {0.25f, 0.75f, 0, 1, 1},
                                 {2.25f, 0.25f, 0, 3, 3},
                                 {4.25f, 0.25f, 1, 0, 2},
                                 {9.0f, 9.0f, kInvalidId, kInvalidId, 0}};
  std::vector<Ray> rays;
  for (const Aim& a : aims) rays.push_back(Ray{Vec3f(a.x, a.y, 10), Vec3f(0, 0, -1)});
  const std::string rays_path = dir.file("rays.npy"), hits_path = dir.file("hits.npy");
  ASSERT_TRUE(write_rays_npy(rays_path, rays).ok());
  const SubprocessResult traced = outcore({"trace", store, "--rays", rays_path, "-o", hits_path});
  ASSERT_TRUE(traced.succeeded()) << traced.describe();
  const auto hits = read_hits_npy(hits_path);
  ASSERT_TRUE(hits.ok()) << hits.status().to_string();
  ASSERT_EQ(hits->size(), aims.size());
  for (std::size_t i = 0; i < aims.size(); ++i) {
    SCOPED_TRACE("ray " + std::to_string(i));
    EXPECT_EQ((*hits)[i].geometry_id, aims[i].geometry_id);
    EXPECT_EQ((*hits)[i].primitive_id, aims[i].primitive_id);
    if (aims[i].geometry_id != kInvalidId) {
      EXPECT_FLOAT_EQ((*hits)[i].t, 10.0f - aims[i].z);
    }
  }
}

TEST(PackCliNpz, AMalformedNpzFailsNamingFileMemberAndRowAndLeavesNothing) {
  TempDir in, out;
  const std::string npz = in.file("bad.npz");
  std::vector<int64_t> triangles = kTriangles;
  triangles[4] = 7;  // row 1 names vertex 7 of 7
  write_npz_mesh(npz, kVertices, triangles, /*deflate=*/true);
  const std::string store = out.file("scene");
  const SubprocessResult r = outcore({"pack", "gen:sphere?level=1", npz, "-o", store, "-q", "--no-sync"});
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(
      contains(r.stderr_text, npz + ", member triangles: row 1: vertex index 7 out of range (7 vertices)"))
      << r.stderr_text;
  EXPECT_TRUE(fs::is_empty(out.path()));
}

TEST(PackCliNpz, AMeshLargerThanHalfOfMemMbIsRefusedNamingTheFileAndTheOption) {
  TempDir in, out;
  const std::string npz = in.file("big.npz");
  // 1.5 M triangles (18 MB held) over one vertex: more than half of --mem-mb
  // 32, yet a small file (deflated zeros).
  write_npz_mesh(npz, {0, 0, 0}, std::vector<int64_t>(3 * 1'500'000, 0), /*deflate=*/true);
  const SubprocessResult r =
      outcore({"pack", npz, "-o", out.file("scene"), "-q", "--no-sync", "--mem-mb", "32"});
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, npz)) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "half of --mem-mb 32")) << r.stderr_text;
  EXPECT_TRUE(fs::is_empty(out.path()));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
