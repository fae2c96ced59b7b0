// Tests of the cost profile (cost_profile.h): the text format round trips,
// every malformed profile is an error naming the file and line, the
// built-in profile covers every auto candidate with sane costs, and the
// default location follows OUTCORE_COST_PROFILE and XDG_CONFIG_HOME.
#include "core/accel/auto/cost_profile.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "core/accel/auto/auto_brick.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

constexpr const char* kHeader =
    "# outcore cost profile, version 1\n"
    "features constant log2_triangles density_spread flatness log2_area_ratio\n";

TEST(CostProfile, FormatThenParseGivesTheSameProfile) {
  CostProfile profile;
  profile.machine = "test box";
  StructureCost cost;
  cost.structure = "grid";
  cost.build = {-15.5, 0.125, -0.25, 1e-9, 3};
  cost.trace = {-14, 0.0625, 0, -1.5, 0.333333333};
  profile.structures.push_back(cost);
  auto parsed = parse_cost_profile(format_cost_profile(profile), "p.txt");
  ASSERT_TRUE(parsed.ok()) << parsed.status().to_string();
  EXPECT_EQ(parsed->machine, "test box");
  EXPECT_EQ(parsed->origin, "p.txt");
  ASSERT_EQ(parsed->structures.size(), 1u);
  EXPECT_EQ(parsed->structures[0].structure, "grid");
  for (std::size_t i = 0; i < kFeatureCount; ++i) {
    EXPECT_NEAR(parsed->structures[0].build[i], cost.build[i], 1e-8 * std::abs(cost.build[i]));
    EXPECT_NEAR(parsed->structures[0].trace[i], cost.trace[i], 1e-8 * std::abs(cost.trace[i]));
  }
}

TEST(CostProfile, MalformedProfilesAreErrorsNamingFileAndLine) {
  const std::string both = "build bvh -16 0 0 0 0\ntrace bvh -16 0 0 0 0\n";
  struct Case {
    std::string text, message;
  } cases[] = {
      {"", "p.txt: empty"},
      {"hello\n", "p.txt:1: not an outcore cost profile"},
      {"# outcore cost profile, version 2\n",
       "p.txt:1: cost profile version 2; this outcore reads version 1"},
      {"# outcore cost profile, version x\n", "p.txt:1: unreadable version"},
      {std::string(kHeader) + "colour red\n", "p.txt:3: unknown item 'colour'"},
      {"# outcore cost profile, version 1\n" + both, "p.txt:2: the 'features' line must come first"},
      {"# outcore cost profile, version 1\nfeatures constant size\n", "p.txt:2: features must be listed as"},
      {std::string(kHeader) + "build bvh -16 0 0 0\n", "p.txt:3: 'build' needs a structure and 5 numbers"},
      {std::string(kHeader) + "build bvh -16 0 zero 0 0\n", "p.txt:3: coefficient density_spread of 'bvh'"},
      {std::string(kHeader) + "build bvh -16 0 nan 0 0\n", "p.txt:3: coefficient density_spread of 'bvh'"},
      {std::string(kHeader) + "build bvh -16 0 1e9 0 0\n", "magnitude <= 1000"},
      {std::string(kHeader) + both + "trace bvh -16 0 0 0 0\n", "p.txt:5: a second 'trace' line for 'bvh'"},
      {std::string(kHeader) + "build bvh -16 0 0 0 0\n", "p.txt: structure 'bvh' has no 'trace' line"},
      {std::string(kHeader), "p.txt: names no structure"},
  };
  for (const Case& c : cases) {
    auto parsed = parse_cost_profile(c.text, "p.txt");
    ASSERT_FALSE(parsed.ok()) << c.message;
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(parsed.status().message().find(c.message), std::string::npos) << parsed.status().to_string();
  }
  EXPECT_TRUE(parse_cost_profile(std::string(kHeader) + "\n# a comment\r\n" + both, "p.txt").ok());
}

TEST(CostProfile, TheBuiltInProfileCoversEveryCandidateWithSaneCosts) {
  const CostProfile& builtin = builtin_cost_profile();
  EXPECT_EQ(builtin.origin, "built-in");
  BrickFeatures small, large;
  small.triangles = 1000, small.area_ratio = 1, small.flatness = 0.5, small.density_spread = 1;
  large = small;
  large.triangles = 100000;
  for (const char* name : kDefaultAutoCandidates) {
    const StructureCost* cost = builtin.find(name);
    ASSERT_NE(cost, nullptr) << name;
    // Between a nanosecond and a millisecond per triangle built and per ray traced.
    for (const BrickFeatures& f : {small, large}) {
      EXPECT_GT(cost->build_seconds(f) / f.triangles, 1e-9) << name;
      EXPECT_LT(cost->build_seconds(f) / f.triangles, 1e-3) << name;
      EXPECT_GT(cost->trace_seconds_per_ray(f), 1e-9) << name;
      EXPECT_LT(cost->trace_seconds_per_ray(f), 1e-3) << name;
    }
    EXPECT_GT(cost->build_seconds(large), cost->build_seconds(small)) << name;
  }
}

class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old, had_ = true;
    if (value)
      setenv(name, value, 1);
    else
      unsetenv(name);
  }
  ~ScopedEnv() {
    if (had_)
      setenv(name_, old_.c_str(), 1);
    else
      unsetenv(name_);
  }

 private:
  const char* name_;
  std::string old_;
  bool had_ = false;
};

TEST(CostProfile, TheDefaultPathFollowsTheEnvironmentAndFallsBackToTheBuiltIn) {
  testing::TempDir dir;
  {
    ScopedEnv profile("OUTCORE_COST_PROFILE", nullptr);
    ScopedEnv xdg("XDG_CONFIG_HOME", dir.path().c_str());
    EXPECT_EQ(default_cost_profile_path(), dir.path() + "/outcore/cost_profile.txt");
    auto resolved = resolve_cost_profile("");
    ASSERT_TRUE(resolved.ok());
    EXPECT_EQ(resolved->origin, "built-in");  // no file there
    ScopedEnv home("HOME", "/home/someone");
    ScopedEnv no_xdg("XDG_CONFIG_HOME", nullptr);
    EXPECT_EQ(default_cost_profile_path(), "/home/someone/.config/outcore/cost_profile.txt");
  }
  const std::string path = dir.path() + "/mine.txt";
  std::ofstream(path) << kHeader << "build bvh -16 0 0 0 0\ntrace bvh -16 0 0 0 0\n";
  ScopedEnv profile("OUTCORE_COST_PROFILE", path.c_str());
  EXPECT_EQ(default_cost_profile_path(), path);
  auto resolved = resolve_cost_profile("");
  ASSERT_TRUE(resolved.ok()) << resolved.status().to_string();
  EXPECT_EQ(resolved->origin, path);
  // A named file must exist; a broken default is an error, not the built-in.
  EXPECT_EQ(resolve_cost_profile(dir.path() + "/none.txt").status().code(), StatusCode::kNotFound);
  std::ofstream(path) << "garbage\n";
  EXPECT_EQ(resolve_cost_profile("").status().code(), StatusCode::kInvalidArgument);
}

TEST(CostProfile, SaveWritesWhatLoadReads) {
  testing::TempDir dir;
  const std::string path = dir.path() + "/p.txt";
  ASSERT_TRUE(save_cost_profile(builtin_cost_profile(), path).ok());
  auto loaded = load_cost_profile(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
  EXPECT_EQ(loaded->structures.size(), builtin_cost_profile().structures.size());
  EXPECT_EQ(loaded->machine, builtin_cost_profile().machine);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
