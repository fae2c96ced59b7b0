// Tests of calibration (calibration.h): the fit recovers known
// coefficients from exact log-linear costs and gives unvaried features no
// weight; calibrate() measures real builds and traces into a valid profile;
// store samples are spread over the brick sizes; errors name the structure.
#include "core/calibrate/calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(Calibration, TheFitRecoversKnownCoefficients) {
  const std::array<double, kFeatureCount> build = {-15, 0.1, -0.2, 0.3, 0.05};
  const std::array<double, kFeatureCount> trace = {-16, 0.08, 0.1, -0.4, 0.2};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<CalibrationSample> samples;
  for (int k = 0; k < 40; ++k) {
    CalibrationSample s;
    s.features.triangles = static_cast<uint32_t>(100 + u(rng) * 200000);
    s.features.density_spread = 6 * u(rng);
    s.features.flatness = u(rng);
    s.features.area_ratio = 8 * u(rng);
    StructureCost truth{"bvh", build, trace};
    s.measures.push_back({truth.build_seconds(s.features), truth.trace_seconds_per_ray(s.features)});
    samples.push_back(s);
  }
  const CostProfile profile = fit_cost_profile({"bvh"}, samples);
  ASSERT_EQ(profile.structures.size(), 1u);
  ASSERT_EQ(profile.samples.size(), samples.size());
  // The ridge pulls the coefficients slightly towards 0: predictions stay
  // within ~10 % over this wide a range of features.
  for (const CalibrationSample& s : samples) {
    EXPECT_NEAR(profile.structures[0].build_seconds(s.features) / s.measures[0].build_seconds, 1.0, 0.12);
    EXPECT_NEAR(profile.structures[0].trace_seconds_per_ray(s.features) / s.measures[0].trace_seconds_per_ray,
                1.0, 0.12);
  }
}

TEST(Calibration, AFeatureTheSamplesDoNotVaryGetsNoWeight) {
  std::vector<CalibrationSample> samples;
  for (uint32_t n = 100; n < 1000000; n *= 3) {
    CalibrationSample s;
    s.features.triangles = n;
    s.features.flatness = 1, s.features.area_ratio = 1, s.features.density_spread = 0;
    s.measures.push_back({1e-7 * n, 1e-7 * std::log2(n)});
    samples.push_back(s);
  }
  const CostProfile profile = fit_cost_profile({"grid"}, samples);
  EXPECT_EQ(profile.structures[0].build[2], 0.0);  // density_spread: always 0
  // A brick unlike the samples (spread 6) is predicted as the samples' model says, not wildly.
  BrickFeatures odd = samples[3].features;
  odd.density_spread = 6;
  EXPECT_NEAR(profile.structures[0].build_seconds(odd) / samples[3].measures[0].build_seconds, 1.0, 0.2);
}

TEST(Calibration, MeasuresRealStructuresAndFitsAProfileNamingThem) {
  auto samples = builtin_sample_bricks();
  ASSERT_TRUE(samples.ok()) << samples.status().to_string();
  ASSERT_EQ(samples->size(), builtin_sample_specs().size());
  // Three of them keep the test short: the smallest, a mid-sized sphere, a terrain.
  std::vector<SampleBrick> few;
  for (const SampleBrick& s : *samples) {
    if (s.label == "gen:sphere?level=1" || s.label == "gen:sphere?level=5" ||
        s.label == "gen:terrain?n=30&size=10&height=1")
      few.push_back(s);
  }
  ASSERT_EQ(few.size(), 3u);
  CalibrationOptions options;
  options.structures = {"bvh", "grid"};
  options.rays_per_brick = 512;
  options.min_seconds_per_measure = 0.001;
  int measured = 0;
  options.on_measured = [&] { ++measured; };
  auto calibration = calibrate(few, options);
  ASSERT_TRUE(calibration.ok()) << calibration.status().to_string();
  EXPECT_EQ(measured, 6);
  ASSERT_EQ(calibration->samples.size(), 3u);
  for (const CalibrationSample& s : calibration->samples) {
    ASSERT_EQ(s.measures.size(), 2u);
    for (const StructureMeasure& m : s.measures) {
      EXPECT_GT(m.build_seconds, 0);
      EXPECT_GT(m.trace_seconds_per_ray, 0);
      EXPECT_LT(m.trace_seconds_per_ray, 1e-3);
    }
  }
  // The profile is a valid one and names both.
  auto reparsed = parse_cost_profile(format_cost_profile(calibration->profile), "fit");
  ASSERT_TRUE(reparsed.ok()) << reparsed.status().to_string();
  EXPECT_NE(reparsed->find("bvh"), nullptr);
  EXPECT_NE(reparsed->find("grid"), nullptr);
  EXPECT_EQ(reparsed->samples.size(), 3u);
}

TEST(Calibration, ErrorsNameTheStructure) {
  auto samples = builtin_sample_bricks();
  ASSERT_TRUE(samples.ok());
  samples->resize(1);
  CalibrationOptions options;
  options.structures = {"bvh", "octagon"};
  auto calibration = calibrate(*samples, options);
  ASSERT_FALSE(calibration.ok());
  EXPECT_NE(calibration.status().message().find("unknown brick accel 'octagon'"), std::string::npos);
  options.structures = {"bvh"};
  EXPECT_FALSE(calibrate({}, options).ok());
}

TEST(Calibration, StoreSamplesSpreadOverTheBrickSizes) {
  auto scene = testing::pack_test_scene(
      {testing::model_path("stanford-bunny.obj"), "gen:sphere?level=2", "gen:terrain?n=30&size=3&height=0.2"},
      1024);
  auto store = SceneStore::open(scene->path);
  ASSERT_TRUE(store.ok());
  auto samples = sample_store_bricks(**store, 5);
  ASSERT_TRUE(samples.ok()) << samples.status().to_string();
  ASSERT_EQ(samples->size(), 5u);
  uint32_t smallest = UINT32_MAX, largest = 0;
  for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
    smallest = std::min(smallest, (*store)->manifest().bricks[b].triangle_count);
    largest = std::max(largest, (*store)->manifest().bricks[b].triangle_count);
  }
  EXPECT_EQ(samples->front().data.triangles.size(), smallest);
  EXPECT_EQ(samples->back().data.triangles.size(), largest);
  for (const SampleBrick& s : *samples) EXPECT_EQ(s.label.rfind("brick ", 0), 0u);
  auto all = sample_store_bricks(**store, 100000);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), (*store)->brick_count());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
