// Calibration: measures what building and tracing each brick structure costs
// on this machine, on sample bricks (of a store, or of built-in procedural
// scenes), and fits the cost model of `--brick-accel auto` to it
// (core/accel/auto/cost_profile.h). `outcore calibrate` runs it.
//
// Measurements run on the calling thread, one at a time (the engine builds
// one brick per thread, so a single thread's cost is the one to model). Each
// build and trace is repeated until it has run for a few milliseconds, and
// the fastest repetition is kept (the least disturbed by other processes).
//
// Thread-safety: functions of their arguments.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/accel/auto/brick_features.h"
#include "core/accel/auto/cost_profile.h"
#include "core/accel/brick_accel_factory.h"
#include "core/store/brick_data.h"
#include "core/store/scene_store.h"
#include "core/util/status.h"

namespace outcore {

struct SampleBrick {
  std::string label;  // "brick 12" or the generator spec
  BrickData data;
};

struct CalibrationOptions {
  std::vector<std::string> structures;  // empty: auto's default candidates
  BrickAccelOptions structure_options;  // given to each (triangle_test)
  uint32_t rays_per_brick = 4096;       // incoherent rays through the brick's box
  double min_seconds_per_measure = 0.004;
  uint64_t seed = 1;
  // Called after each (sample, structure) measurement, for progress.
  std::function<void()> on_measured;
};

struct StructureMeasure {
  double build_seconds = 0;          // one build, fastest repetition
  double trace_seconds_per_ray = 0;  // closest hit, fastest repetition
};

struct CalibrationSample {
  std::string label;
  BrickFeatures features;
  std::vector<StructureMeasure> measures;  // per CalibrationOptions structure
};

struct Calibration {
  std::vector<std::string> structures;
  std::vector<CalibrationSample> samples;
  CostProfile profile;
};

// Up to `max_bricks` bricks of `store` spread over its brick sizes (smallest
// to largest, evenly by rank), loaded (checksums verified).
Expected<std::vector<SampleBrick>> sample_store_bricks(const SceneStore& store, uint32_t max_bricks);
// Bricks of built-in procedural scenes: spheres, a torus, terrains, teapots
// in stadiums and sparse cities, from ~100 to ~100 k triangles.
Expected<std::vector<SampleBrick>> builtin_sample_bricks();
// The specs builtin_sample_bricks() generates (for docs and tests).
const std::vector<std::string>& builtin_sample_specs();

// Measures every structure on every sample and fits the profile.
Expected<Calibration> calibrate(std::vector<SampleBrick> samples, const CalibrationOptions& options);

// The least-squares fit of the profile's coefficients to `samples` (log
// costs, a small ridge on all but the constant so that a feature the samples
// do not vary gets no weight).
CostProfile fit_cost_profile(const std::vector<std::string>& structures,
                             const std::vector<CalibrationSample>& samples);

}  // namespace outcore
