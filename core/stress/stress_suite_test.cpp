// The numerical stress suite in CI: the watertight configurations
// (bvh-watertight, bvh-double) never leak and never disagree with the float64
// reference in any case, at any offset or scale, and tiny bricks answer
// exactly as one brick does. Under sanitizers every 16th vertex and edge
// midpoint is aimed at instead of all of them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/stress/stress_runner.h"
#include "core/stress/stress_scenes.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

#ifdef OUTCORE_SANITIZE_BUILD
constexpr uint32_t kStride = 16;
constexpr uint32_t kChecked = 100;
#else
constexpr uint32_t kStride = 1;
constexpr uint32_t kChecked = 400;
#endif

// A static object, not a leaked pointer: its destructor removes the seam
// scenes' packed stores from the temporary directory when the tests exit.
const StressScenes& scenes() {
  static const StressScenes kScenes = [] {
    StressOptions options;
    options.quick = true;
    options.models_dir = OUTCORE_MODELS_DIR;
    options.stride = kStride;
    auto made = make_stress_scenes(options);
    EXPECT_TRUE(made.ok()) << made.status().to_string();
    return made.ok() ? std::move(made).value() : StressScenes{};
  }();
  return kScenes;
}

const StressConfig& config(const std::string& name) {
  for (const auto& c : stress_configs()) {
    if (c.name == name) return c;
  }
  ADD_FAILURE() << name;
  return stress_configs().front();
}

TEST(StressSuite, CoversEveryFamilyEveryClosedModelAndEveryVariant) {
  std::vector<std::string> names;
  for (const auto& s : scenes().scenes) {
    names.push_back(s.name);
    EXPECT_EQ(s.rays.size(), s.expect.size()) << s.name;
    EXPECT_FALSE(s.rays.empty()) << s.name;
  }
  for (const auto& note : scenes().notes) std::printf("note: %s\n", note.c_str());
  for (const char* mesh : {"sphere", "torus", "fandisk", "homer", "spot", "beast"}) {
    for (const char* variant : {"", " +1e3", " +1e5", " +1e6", " x1e-4", " x1e6"}) {
      const std::string name = std::string(mesh) + variant;
      EXPECT_NE(std::find(names.begin(), names.end(), name), names.end()) << name << " missing";
    }
  }
  for (const char* family : {"closed", "axis", "grazing", "sliver", "segment", "seam"}) {
    bool found = false;
    for (const auto& s : scenes().scenes) found = found || s.family == family;
    EXPECT_TRUE(found) << family;
  }
}

TEST(StressSuite, WorkspacesAreDistinctAndRemovedWithTheirLastOwner) {
  std::filesystem::path first_path;
  {
    auto first = StressWorkspace::create();
    auto second = StressWorkspace::create();
    ASSERT_TRUE(first.ok() && second.ok());
    first_path = (*first)->path();
    EXPECT_NE(first_path, (*second)->path());
    EXPECT_TRUE(std::filesystem::is_directory(first_path));
    EXPECT_TRUE(std::filesystem::is_directory((*second)->path()));
  }
  EXPECT_FALSE(std::filesystem::exists(first_path));
}

TEST(StressSuite, InteriorPointsAreInside) {
  for (const auto& s : scenes().scenes) {
    if (s.family != "closed") continue;
    EXPECT_TRUE(inside_by_parity(s.triangles, s.rays.front().origin)) << s.name;
  }
  const auto& sphere = scenes().scenes.front();
  EXPECT_FALSE(inside_by_parity(sphere.triangles, Vec3f(3, 0.1f, 0.2f)));
}

// Zero leaks and identical answers across brick seams. Wrong hits: none for
// bvh-double (the same float64 test as the reference, so this checks that
// no box culls a hit); for bvh-watertight at most 1% of the checked rays
// outside the grazing family: a ray aimed exactly at a silhouette vertex
// touches the surface tangentially, and float and double may decide that
// contact differently (the ray then hits the surface behind: not a leak).
// Rays in a face's plane (grazing) are reported only.
void expect_watertight(const std::string& config_name, bool exact) {
  std::vector<StressRow> rows;
  for (const auto& scene : scenes().scenes) {
    const StressReference reference = compute_stress_reference(scene, kChecked);
    auto row = run_stress(scene, reference, config(config_name));
    ASSERT_TRUE(row.ok()) << row.status().to_string();
    EXPECT_EQ(row->leaks, 0u) << scene.name;
    if (exact) {
      EXPECT_EQ(row->wrong_hits, 0u) << scene.name;
      EXPECT_LE(row->max_rel_t_error, 1e-6) << scene.name;
    } else if (scene.family != "grazing") {
      EXPECT_LE(row->wrong_hits, std::max<uint64_t>(2, row->checked / 100)) << scene.name;
    }
    if (scene.family == "seam") {
      EXPECT_EQ(row->seam_diffs, 0) << scene.name;
    }
    rows.push_back(*row);
  }
  std::fputs(format_stress_table(rows).c_str(), stdout);
}

TEST(StressSuite, BvhWatertightNeverLeaks) {
  expect_watertight("bvh-watertight", false);
}

TEST(StressSuite, BvhDoubleNeverLeaksAndAgreesWithTheReference) {
  expect_watertight("bvh-double", true);
}

// The split-plane trees (issue 24) are held to the bvh's bar on every scene.
// Under the sanitizers (a Debug build, where the BSP's build is slow) each
// test runs one of the two trees; the release run checks all four.
TEST(StressSuite, KdTreeAndBspWatertightNeverLeak) {
  expect_watertight("kdtree-watertight", false);
#ifndef OUTCORE_SANITIZE_BUILD
  expect_watertight("bsp-watertight", false);
#endif
}

TEST(StressSuite, KdTreeAndBspDoubleNeverLeakAndAgreeWithTheReference) {
#ifndef OUTCORE_SANITIZE_BUILD
  expect_watertight("kdtree-double", true);
#endif
  expect_watertight("bsp-double", true);
}

// The uniform grid (issue 25) is held to the same bar; the mailboxed DDA's
// conservative runs are what rays along cell boundaries and through corners
// test.
TEST(StressSuite, GridWatertightNeverLeaks) {
  expect_watertight("grid-watertight", false);
}

TEST(StressSuite, GridDoubleNeverLeaksAndAgreesWithTheReference) {
  expect_watertight("grid-double", true);
}

// The hierarchical grid (issue 25), likewise: both levels' walks are the
// grid's conservative DDA.
TEST(StressSuite, HgridWatertightNeverLeaks) {
  expect_watertight("hgrid-watertight", false);
}

TEST(StressSuite, HgridDoubleNeverLeaksAndAgreesWithTheReference) {
  expect_watertight("hgrid-double", true);
}

// The octree (issue 25), likewise: its walk is conservative at middle planes
// and where eight cells meet.
TEST(StressSuite, OctreeWatertightNeverLeaks) {
  expect_watertight("octree-watertight", false);
}

TEST(StressSuite, OctreeDoubleNeverLeaksAndAgreesWithTheReference) {
  expect_watertight("octree-double", true);
}

// The quadtree (issue 25), likewise: conservative at middle lines, where
// four columns meet and at the columns' height bounds.
TEST(StressSuite, QuadtreeWatertightNeverLeaks) {
  expect_watertight("quadtree-watertight", false);
}

TEST(StressSuite, QuadtreeDoubleNeverLeaksAndAgreesWithTheReference) {
  expect_watertight("quadtree-double", true);
}

// The suite is not vacuous: Möller–Trumbore in float leaks through shared
// vertices and edges somewhere in it.
TEST(StressSuite, MollerTrumboreLeaksSomewhere) {
  uint64_t leaks = 0;
  for (const auto& scene : scenes().scenes) {
    if (scene.family != "closed" && scene.family != "sliver") continue;
    auto row = run_stress(scene, StressReference{}, config("bvh-mt"));
    ASSERT_TRUE(row.ok()) << row.status().to_string();
    leaks += row->leaks;
  }
  EXPECT_GT(leaks, 0u);
}

TEST(StressSuite, ConfigSelectionRejectsUnknownNames) {
  EXPECT_EQ(select_stress_configs("all")->size(), 17u);
  EXPECT_EQ(select_stress_configs("bvh-mt")->front().name, "bvh-mt");
  const auto bad = select_stress_configs("bvh");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("embree-robust"), std::string::npos) << bad.status().message();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
