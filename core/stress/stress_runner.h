// Runs the stress scenes (stress_scenes.h) with a brick-structure
// configuration and measures, per scene: rays, leaks (rays that must hit and
// miss), wrong hits (rays that must miss and hit, and against the float64
// reference a different hit/miss, or a different triangle at a distance that
// is not a tie: relative difference above kTieTolerance), the
// largest relative t error against the reference, and for seam scenes how
// many answers differ bitwise between tiny bricks and one brick.
//
// The reference is the float64 watertight test (double_triangle_test.h) by
// brute force over all the scene's triangles, with the tie rule; it is
// computed once per scene for up to max_checked rays (evenly spaced) and
// shared by every configuration.
//
// Configurations: embree, embree-robust, bvh-mt, bvh-watertight, bvh-double,
// and the split-plane trees and the grid with the exact tests:
// kdtree-watertight, kdtree-double, bsp-watertight, bsp-double,
// grid-watertight, grid-double, hgrid-watertight, hgrid-double,
// octree-watertight, octree-double,
// quadtree-watertight, quadtree-double
// (bvh-watertight, bvh-double and the
// structures with exact tests must never leak:
// StressConfig::must_not_leak).
//
// Thread-safety: plain functions; run_stress uses the engine's threads for
// seam scenes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/stress/stress_scenes.h"
#include "core/util/status.h"

namespace outcore {

struct StressConfig {
  std::string name;
  std::string accel;
  BrickAccelOptions options;
  bool must_not_leak = false;
};

const std::vector<StressConfig>& stress_configs();
// "all" or one configuration's name; anything else is INVALID_ARGUMENT
// listing the names.
Expected<std::vector<StressConfig>> select_stress_configs(const std::string& which);

// Relative t difference under which two hits on different triangles are a
// tie (the same point, e.g. a shared vertex), not a wrong hit.
inline constexpr double kTieTolerance = 1e-5;

struct StressReference {
  std::vector<uint32_t> checked;  // ray indices with a reference answer
  std::vector<double> t;          // per checked ray; inf on a miss
  std::vector<TriangleId> id;
};
StressReference compute_stress_reference(const StressScene& scene, uint32_t max_checked);

struct StressRow {
  std::string scene;
  std::string family;
  std::string config;
  uint64_t rays = 0;
  uint64_t leaks = 0;
  uint64_t checked = 0;
  uint64_t wrong_hits = 0;
  double max_rel_t_error = 0;
  int64_t seam_diffs = -1;  // seam scenes only
};

Expected<StressRow> run_stress(const StressScene& scene, const StressReference& reference,
                               const StressConfig& config);

// One table, a row per (scene, config).
std::string format_stress_table(const std::vector<StressRow>& rows);

}  // namespace outcore
