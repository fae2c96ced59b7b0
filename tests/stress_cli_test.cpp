// End-to-end tests of the accuracy commands, run as the real binary:
// `outcore trace --reference` (float64 ground truth on the same store) agrees
// with the brute-force reference and bitwise with --brick-accel bvh
// --triangle-test double; --triangle-test needs --brick-accel bvh; `outcore
// stress` prints its table and rejects unknown configurations.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "core/accel/brute_force_reference.h"
#include "core/io/npy.h"
#include "core/store/scene_store.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::SubprocessResult;
using testing::TempDir;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(120'000));
}

class AccuracyCli : public ::testing::Test {
 protected:
  void SetUp() override {
    store_ = dir_.file("scene");
    const auto packed =
        outcore({"pack", "gen:sphere?level=3", "gen:torus?cx=3", "-o", store_, "--brick-tris", "64"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<float> u(-1.5f, 1.5f);
    for (int i = 0; i < 1500; ++i) {
      Ray r;
      r.origin = {u(rng) * 3, u(rng) * 3, u(rng) * 3};
      r.direction = Vec3f(u(rng) + 1.5f, u(rng), u(rng)) - r.origin;
      if (i % 5 == 0) r.origin = {0, 0, 0};  // inside the sphere
      rays_.push_back(r);
    }
    rays_path_ = dir_.file("rays.npy");
    ASSERT_TRUE(write_rays_npy(rays_path_, rays_).ok());
  }

  std::vector<Hit> trace(const std::vector<std::string>& extra, const std::string& name) {
    std::vector<std::string> args = {"trace", store_, "--rays", rays_path_, "-o", dir_.file(name)};
    args.insert(args.end(), extra.begin(), extra.end());
    const auto r = outcore(args);
    EXPECT_TRUE(r.succeeded()) << r.describe();
    auto hits = read_hits_npy(dir_.file(name));
    EXPECT_TRUE(hits.ok()) << hits.status().to_string();
    return hits.ok() ? *hits : std::vector<Hit>{};
  }

  TempDir dir_;
  std::string store_, rays_path_;
  std::vector<Ray> rays_;
};

TEST_F(AccuracyCli, ReferenceAgreesWithTheBruteForceAndWithBvhDouble) {
  const auto reference = trace({"--reference"}, "ref.npy");
  ASSERT_EQ(reference.size(), rays_.size());
  auto store = SceneStore::open(store_);
  ASSERT_TRUE(store.ok());
  std::vector<Triangle> tris;
  std::vector<TriangleId> ids;
  BrickData brick;
  for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
    ASSERT_TRUE((*store)->load_brick(b, brick).ok());
    tris.insert(tris.end(), brick.triangles.begin(), brick.triangles.end());
    ids.insert(ids.end(), brick.ids.begin(), brick.ids.end());
  }
  std::size_t hits = 0, disagreements = 0;
  for (std::size_t i = 0; i < rays_.size(); ++i) {
    const ReferenceHit want = reference_closest_hit(tris, ids, rays_[i]);
    if (want.is_hit() != reference[i].is_hit()) {
      ++disagreements;  // only at an exact edge graze
      continue;
    }
    if (!want.is_hit()) continue;
    ++hits;
    EXPECT_EQ(reference[i].t, static_cast<float>(want.t)) << "ray " << i;
    if (reference[i].primitive_id != want.primitive_id || reference[i].geometry_id != want.geometry_id) {
      ++disagreements;
    }
  }
  EXPECT_GT(hits, rays_.size() / 4);
  EXPECT_LE(disagreements, 2u);
  const auto bvh_double = trace({"--brick-accel", "bvh", "--triangle-test", "double"}, "double.npy");
  ASSERT_EQ(bvh_double.size(), reference.size());
  EXPECT_EQ(std::memcmp(bvh_double.data(), reference.data(), reference.size() * sizeof(Hit)), 0);
  for (const char* test : {"mt", "watertight"}) {
    const auto other = trace({"--brick-accel", "bvh", "--triangle-test", test}, std::string(test) + ".npy");
    std::size_t differ = 0;
    for (std::size_t i = 0; i < rays_.size(); ++i) differ += other[i].is_hit() != reference[i].is_hit();
    EXPECT_LE(differ, 2u) << test;
  }
}

TEST_F(AccuracyCli, TriangleTestAndReferenceOptionsAreChecked) {
  const std::string out = dir_.file("h.npy");
  auto r = outcore(
      {"trace", store_, "--rays", rays_path_, "-o", out, "--brick-accel", "embree", "--triangle-test", "mt"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "--brick-accel bvh")) << r.stderr_text;
  r = outcore(
      {"trace", store_, "--rays", rays_path_, "-o", out, "--brick-accel", "bvh", "--triangle-test", "exact"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "'exact'")) << r.stderr_text;
  r = outcore({"trace", store_, "--rays", rays_path_, "-o", out, "--brick-accel", "bvh", "--triangle-test",
               "mt", "--accel-opt", "triangle_test=double"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "both given")) << r.stderr_text;
  r = outcore({"trace", store_, "--rays", rays_path_, "-o", out, "--reference", "--brick-accel", "embree"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "--reference")) << r.stderr_text;
  // Any-hit with the reference agrees with its closest hits.
  const auto closest = trace({"--reference"}, "ref.npy");
  r = outcore(
      {"trace", store_, "--rays", rays_path_, "-o", dir_.file("any.npy"), "--reference", "--any-hit"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const auto any = read_bools_npy(dir_.file("any.npy"));
  ASSERT_TRUE(any.ok());
  for (std::size_t i = 0; i < closest.size(); ++i) EXPECT_EQ((*any)[i] != 0, closest[i].is_hit()) << i;
}

TEST(StressCli, PrintsTheTableAndRejectsUnknownConfigurations) {
  // No --models: the repository's tests/data/models is found from the
  // binary's location (the test runs in build/tests, not the repository root).
  auto r = outcore({"stress", "--config", "bvh-watertight", "--quick", "--stride", "8", "--checked", "50"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  for (const char* part : {"case", "config", "rays", "leaks", "wrong", "max rel t", "sphere +1e6",
                           "beast x1e6", "torus seams", "bvh-watertight"}) {
    EXPECT_TRUE(contains(r.stdout_text, part)) << part << " missing in\n" << r.stdout_text;
  }
  r = outcore({"stress", "--config", "optix"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "'optix'")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "bvh-double")) << r.stderr_text;
}

TEST(StressCli, NamesWhereItLookedWhenTheModelsAreMissing) {
  auto r = outcore({"stress", "--quick", "--models", "/nonexistent/outcore-models"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.stderr_text, "/nonexistent/outcore-models")) << r.stderr_text;
  // A binary outside any checkout, run from a directory without the models
  // (its own), finds none: the error lists where it looked and the flags
  // that help.
  TempDir dir;
  const std::string copy = dir.file("outcore");
  std::filesystem::copy_file(testing::outcore_binary(), copy);
  std::filesystem::permissions(copy, std::filesystem::perms::owner_exec, std::filesystem::perm_options::add);
  testing::SubprocessOptions options;
  options.timeout = std::chrono::milliseconds(60'000);
  r = testing::run_subprocess(
      {"/bin/sh", "-c", "cd '" + dir.path() + "' && exec ./outcore stress --quick --config bvh-watertight"},
      options);
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "were not found")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, dir.path() + "/tests/data/models")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "--no-models")) << r.stderr_text;
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
