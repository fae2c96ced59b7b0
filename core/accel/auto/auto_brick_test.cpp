// Tests of `--brick-accel auto` (auto_brick.h): the factory's options and
// their errors, the choice (cheapest build for few rays, cheapest trace for
// many, monotone in between), answers bitwise those of the chosen candidate
// built alone, refinement only when a better structure pays for itself, a
// reservation that bounds every choice, and the serialiser (round trip per
// candidate, malformed payloads refused, fuzzing).
#include "core/accel/auto/auto_brick.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "core/accel/accel_test_util.h"
#include "core/accel/serializer_test_util.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::bounds_of;
using accel_test::rays_from_outside;

std::unique_ptr<AutoBrickBuilder> make_auto(const BrickAccelOptions& options = {}) {
  auto made = make_brick_builder("auto", options);
  EXPECT_TRUE(made.ok()) << made.status().to_string();
  if (!made.ok()) return nullptr;
  return std::unique_ptr<AutoBrickBuilder>(static_cast<AutoBrickBuilder*>(made->release()));
}

BrickData bunny() {
  return accel_test::load_brick_from(accel_test::bunny_path());
}

TEST(AutoBrick, FactoryRejectsBadOptionsNamingThem) {
  struct Case {
    BrickAccelOptions options;
    std::string message;
  } cases[] = {
      {{{"colour", "red"}}, "unknown option 'colour' (known: candidates, triangle_test, profile)"},
      {{{"candidates", "bvh,embree"}}, "candidate 'embree' is not one of"},
      {{{"candidates", "reference"}}, "candidate 'reference' is not one of"},
      {{{"candidates", "bvh,grid,bvh"}}, "candidate 'bvh' listed twice"},
      {{{"candidates", ""}}, "names no structure"},
      {{{"triangle_test", "exact"}}, "triangle_test must be mt, watertight or double"},
      {{{"profile", "/nonexistent/outcore/profile.txt"}},
       "cannot read cost profile /nonexistent/outcore/profile.txt"},
      {{{"profile", ""}}, "option profile needs a file name"},
  };
  for (const Case& c : cases) {
    auto made = make_brick_builder("auto", c.options);
    ASSERT_FALSE(made.ok()) << c.message;
    EXPECT_NE(made.status().message().find(c.message), std::string::npos) << made.status().to_string();
  }
}

TEST(AutoBrick, NamedCandidatesMustBeInTheProfileDefaultOnesAreThoseItHas) {
  testing::TempDir dir;
  const std::string path = dir.path() + "/p.txt";
  std::ofstream(path) << "# outcore cost profile, version 1\n"
                         "features constant log2_triangles density_spread flatness log2_area_ratio\n"
                         "build bvh -16 0 0 0 0\ntrace bvh -16 0 0 0 0\n";
  auto made = make_brick_builder("auto", {{"profile", path}, {"candidates", "bvh,grid"}});
  ASSERT_FALSE(made.ok());
  EXPECT_NE(made.status().message().find("cost profile " + path + " has no costs for candidate 'grid'"),
            std::string::npos)
      << made.status().to_string();
  EXPECT_TRUE(make_brick_builder("auto", {{"profile", path}, {"candidates", "bvh"}}).ok());
  const auto defaults = make_auto({{"profile", path}});
  ASSERT_NE(defaults, nullptr);
  EXPECT_EQ(defaults->candidates(), std::vector<std::string>{"bvh"});
  std::ofstream(path) << "# outcore cost profile, version 1\n"
                         "features constant log2_triangles density_spread flatness log2_area_ratio\n"
                         "build foo -16 0 0 0 0\ntrace foo -16 0 0 0 0\n";
  auto none = make_brick_builder("auto", {{"profile", path}});
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("has costs for none of bvh, kdtree"), std::string::npos)
      << none.status().to_string();
}

TEST(AutoBrick, FewRaysGetTheCheapestBuildManyTheCheapestTraceAndTheChoiceIsMonotone) {
  const auto builder = make_auto();
  ASSERT_NE(builder, nullptr);
  const BrickFeatures features = measure_brick_features(bunny().triangles);
  const auto& costs = builder->profile();
  std::size_t cheapest_build = 0, cheapest_trace = 0;
  const auto& names = builder->candidates();
  for (std::size_t c = 0; c < names.size(); ++c) {
    if (costs.find(names[c])->build_seconds(features) <
        costs.find(names[cheapest_build])->build_seconds(features))
      cheapest_build = c;
    if (costs.find(names[c])->trace_seconds_per_ray(features) <
        costs.find(names[cheapest_trace])->trace_seconds_per_ray(features))
      cheapest_trace = c;
  }
  EXPECT_EQ(builder->choose(features, 0).candidate, cheapest_build);
  EXPECT_EQ(builder->choose(features, uint64_t{1} << 40).candidate, cheapest_trace);
  EXPECT_NE(cheapest_build, cheapest_trace) << "the built-in profile should make the choice matter";
  double last_trace = INFINITY;
  for (uint64_t rays = 1; rays < (uint64_t{1} << 34); rays *= 4) {
    const uint32_t chosen = builder->choose(features, rays).candidate;
    const double trace = costs.find(names[chosen])->trace_seconds_per_ray(features);
    EXPECT_LE(trace, last_trace) << rays << " rays chose " << names[chosen];
    last_trace = trace;
  }
}

TEST(AutoBrick, AnswersAreBitwiseThoseOfTheChosenCandidateBuiltAlone) {
  const BrickData brick = bunny();
  const std::vector<Ray> rays = rays_from_outside(bounds_of(brick), 3000, 5);
  for (const char* candidate : kDefaultAutoCandidates) {
    const auto builder = make_auto({{"candidates", candidate}});
    ASSERT_NE(builder, nullptr);
    BrickData copy = brick;
    auto chosen = builder->build_for(std::move(copy), BuildDemand{10, 10});
    ASSERT_TRUE(chosen.ok()) << chosen.status().to_string();
    EXPECT_EQ(builder->structure_of(**chosen), candidate);
    auto alone_builder = make_brick_builder(candidate, {});
    ASSERT_TRUE(alone_builder.ok());
    copy = brick;
    auto alone = (*alone_builder)->build(std::move(copy));
    ASSERT_TRUE(alone.ok());
    serializer_test::expect_same_answers(**alone, **chosen, rays, candidate);
    EXPECT_LE((*chosen)->memory_bytes(), builder->reserve_bytes(brick.triangles.size())) << candidate;
    EXPECT_EQ((*chosen)->triangle_count(), brick.triangles.size());
  }
}

TEST(AutoBrick, TheDemandDecidesTheBuildAndRebuildingOnlyWhenItPays) {
  const auto builder = make_auto();
  ASSERT_NE(builder, nullptr);
  const BrickData brick = bunny();
  const BrickFeatures features = measure_brick_features(brick.triangles);
  const uint32_t few = builder->choose(features, 1).candidate;
  const uint32_t many = builder->choose(features, uint64_t{1} << 32).candidate;
  BrickData copy = brick;
  auto cheap = builder->build_for(std::move(copy), BuildDemand{1, 1});
  ASSERT_TRUE(cheap.ok());
  EXPECT_EQ(builder->structure_of(**cheap), builder->candidates()[few]);
  EXPECT_FALSE(builder->worth_rebuilding(**cheap, BuildDemand{0, 0}));
  EXPECT_FALSE(builder->worth_rebuilding(**cheap, BuildDemand{1, 1}));
  EXPECT_TRUE(builder->worth_rebuilding(**cheap, BuildDemand{1, uint64_t{1} << 32}));
  copy = brick;
  auto best = builder->build_for(std::move(copy), BuildDemand{1, uint64_t{1} << 32});
  ASSERT_TRUE(best.ok());
  EXPECT_EQ(builder->structure_of(**best), builder->candidates()[many]);
  EXPECT_FALSE(builder->worth_rebuilding(**best, BuildDemand{1, uint64_t{1} << 32}));
  // A rebuild is worth it only when it saves the margin: just past the
  // break-even point between the two it is not.
  const StructureCost& a = *builder->profile().find(builder->candidates()[few]);
  const StructureCost& b = *builder->profile().find(builder->candidates()[many]);
  const double saving_per_ray = a.trace_seconds_per_ray(features) - b.trace_seconds_per_ray(features);
  ASSERT_GT(saving_per_ray, 0);
  const auto break_even = static_cast<uint64_t>(b.build_seconds(features) / saving_per_ray) + 1;
  EXPECT_FALSE(builder->worth_rebuilding(**cheap, BuildDemand{1, break_even}));
  // Not an auto brick (another builder's): never.
  auto other = make_brick_builder("bvh", {});
  copy = brick;
  auto plain = (*other)->build(std::move(copy));
  EXPECT_FALSE(builder->worth_rebuilding(**plain, BuildDemand{1, uint64_t{1} << 40}));
  EXPECT_EQ(builder->structure_of(**plain), "auto");
}

TEST(AutoBrick, EveryCandidateRoundTripsThroughTheSerialiser) {
  const BrickData brick = bunny();
  const std::vector<Ray> rays = rays_from_outside(bounds_of(brick), 2000, 9);
  for (const char* candidate : kDefaultAutoCandidates) {
    const auto builder = make_auto({{"candidates", candidate}});
    ASSERT_NE(builder, nullptr);
    ASSERT_NE(builder->serializer(), nullptr);
    BrickData copy = brick;
    auto built = builder->build_for(std::move(copy), BuildDemand{5, 5});
    ASSERT_TRUE(built.ok());
    const std::string bytes = serializer_test::save(*builder->serializer(), **built);
    auto loaded = builder->serializer()->load(serializer_test::unowned(bytes), 3, brick.triangles.size());
    ASSERT_TRUE(loaded.ok()) << candidate << ": " << loaded.status().to_string();
    EXPECT_EQ(builder->structure_of(**loaded), candidate);
    EXPECT_EQ((*loaded)->memory_bytes(), (*built)->memory_bytes()) << candidate;
    serializer_test::expect_same_answers(**built, **loaded, rays, candidate);
    const auto& kept = static_cast<const AutoBrickAccel&>(**loaded).features();
    const auto& made = static_cast<const AutoBrickAccel&>(**built).features();
    EXPECT_EQ(kept.density_spread, made.density_spread);
    EXPECT_EQ(kept.flatness, made.flatness);
    EXPECT_EQ(kept.area_ratio, made.area_ratio);
  }
}

TEST(AutoBrick, TheStructureKeyNamesEveryCandidatesKey) {
  const auto both = make_auto({{"candidates", "bvh,grid"}});
  const auto one = make_auto({{"candidates", "bvh"}});
  const auto mt = make_auto({{"candidates", "bvh,grid"}, {"triangle_test", "mt"}});
  const std::string& key = both->serializer()->structure_key();
  EXPECT_EQ(key.rfind("auto/1 [", 0), 0u) << key;
  EXPECT_NE(key.find(both->candidate_builder(0).serializer()->structure_key()), std::string::npos);
  EXPECT_NE(key.find(both->candidate_builder(1).serializer()->structure_key()), std::string::npos);
  EXPECT_NE(key, one->serializer()->structure_key());
  EXPECT_NE(key, mt->serializer()->structure_key());
}

TEST(AutoBrick, MalformedPayloadsAreRefusedNamingTheBrick) {
  const auto builder = make_auto({{"candidates", "bvh,grid"}});
  BrickData brick = bunny();
  const uint32_t triangles = brick.triangles.size();
  const std::vector<Ray> rays = rays_from_outside(bounds_of(brick), 500, 2);
  auto built = builder->build_for(std::move(brick), BuildDemand{1, 1});
  ASSERT_TRUE(built.ok());
  const std::string bytes = serializer_test::save(*builder->serializer(), **built);
  const auto refused = [&](std::string copy, const std::string& message) {
    auto loaded = builder->serializer()->load(serializer_test::unowned(copy), 7, triangles);
    ASSERT_FALSE(loaded.ok()) << message;
    EXPECT_EQ(loaded.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(loaded.status().message().find(message), std::string::npos) << loaded.status().to_string();
    EXPECT_NE(loaded.status().message().find("brick 7"), std::string::npos) << loaded.status().to_string();
  };
  refused(bytes.substr(0, 40), "truncated");
  std::string bad = bytes;
  bad[0] ^= 1;
  refused(bad, "bad magic");
  bad = bytes;
  const uint32_t candidate = 2;
  std::memcpy(bad.data() + 4, &candidate, 4);
  refused(bad, "candidate 2 of 2");
  refused(bytes + "x", "payload bytes");
  bad = bytes;
  const double nan = std::nan("");
  std::memcpy(bad.data() + 16, &nan, 8);
  refused(bad, "features out of range");
  bad = bytes;
  const double too_flat = 2;
  std::memcpy(bad.data() + 24, &too_flat, 8);
  refused(bad, "features out of range");
  // Not an auto brick.
  auto plain = make_brick_builder("bvh", {});
  auto other = (*plain)->build(bunny());
  std::ostringstream out;
  EXPECT_FALSE(builder->serializer()->save(**other, out).ok());
  const auto outcome = serializer_test::fuzz(*builder->serializer(), bytes, triangles, rays, 64, 200);
  EXPECT_GT(outcome.refused, 0u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
