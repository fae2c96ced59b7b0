// CostProfile: what building and tracing each brick structure costs on a
// machine, as a function of a brick's features (brick_features.h), for
// `--brick-accel auto` to choose a structure per brick. `outcore calibrate`
// measures it (core/calibrate/); without a profile the built-in constants
// below are used (measured on the project's 2-core reference machine).
//
// The model, per structure s and brick features x (BrickFeatures::regressors):
//   build seconds       = triangles * exp(build_s . x)
//   trace seconds / ray =             exp(trace_s . x)
// log-linear, so costs are positive and features act as factors.
//
// Text format, version 1 (one item per line; '#' lines other than the first
// are comments; blank lines are skipped):
//   # outcore cost profile, version 1
//   # machine: <free text>                      (optional, for people)
//   features constant log2_triangles density_spread flatness log2_area_ratio
//   build <structure> <5 numbers>
//   trace <structure> <5 numbers>
//   sample <triangles> <density_spread> <flatness> <area_ratio>   (optional)
// Every structure named needs both lines. sample lines are the features of
// the bricks the profile was measured on (auto considers only structures
// that are the least cost on one of them; without any, a built-in grid of
// probe bricks). Errors name the file and line.
// Default location: $OUTCORE_COST_PROFILE if set, else
// $XDG_CONFIG_HOME/outcore/cost_profile.txt (XDG_CONFIG_HOME defaulting to
// ~/.config); `--profile FILE` overrides it; when no such file exists the
// built-in profile is used.
//
// Thread-safety: plain values and pure functions (save writes one file).
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "core/accel/auto/brick_features.h"
#include "core/util/status.h"

namespace outcore {

inline constexpr int kCostProfileVersion = 1;

struct StructureCost {
  std::string structure;
  std::array<double, kFeatureCount> build{};  // log(build seconds per triangle)
  std::array<double, kFeatureCount> trace{};  // log(trace seconds per ray)

  double build_seconds(const BrickFeatures& features) const;
  double trace_seconds_per_ray(const BrickFeatures& features) const;
};

struct CostProfile {
  std::string origin;   // "built-in" or the file it was read from
  std::string machine;  // the "# machine:" line, when there is one
  std::vector<StructureCost> structures;
  std::vector<BrickFeatures> samples;

  const StructureCost* find(std::string_view structure) const;
};

Expected<CostProfile> parse_cost_profile(std::string_view text, const std::string& origin);
Expected<CostProfile> load_cost_profile(const std::string& path);
std::string format_cost_profile(const CostProfile& profile);
// Written atomically (a reader sees the old profile or the new one).
Status save_cost_profile(const CostProfile& profile, const std::string& path);

// The constants used without a profile (docs/AUTO.md says where they came from).
const CostProfile& builtin_cost_profile();
// Where calibrate writes and auto reads a profile by default (see above).
std::string default_cost_profile_path();
// The profile at `path` (empty: the default path, falling back to the
// built-in profile when no file is there; a named path must exist).
Expected<CostProfile> resolve_cost_profile(const std::string& path);

}  // namespace outcore
