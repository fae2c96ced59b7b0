// BrickFeatures: what the cost model (cost_profile.h) knows about a brick
// before choosing its structure, all from one pass over its triangles:
// how many there are, how flat the brick is, how unevenly they fill it (the
// "teapot in a stadium") and how much surface they carry for its size.
//
// Thread-safety: a plain value and a pure function.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/geometry/triangle.h"

namespace outcore {

// The regressors of the cost model, in this order; kFeatureNames names them
// in profiles and reports.
inline constexpr std::size_t kFeatureCount = 5;
inline constexpr std::array<const char*, kFeatureCount> kFeatureNames = {
    "constant", "log2_triangles", "density_spread", "flatness", "log2_area_ratio"};

struct BrickFeatures {
  uint32_t triangles = 0;
  // log2 of (the fullest of 4x4x4 cells over the bounds, by triangle
  // centroids) / (the mean cell): 0 when evenly spread, 6 when all in one.
  double density_spread = 0;
  // The thinnest extent of the bounds over the widest: 0 for a plane.
  double flatness = 0;
  // The triangles' total area over the bounds' surface area (a closed
  // surface filling its box is about 1; a dense soup far more).
  double area_ratio = 0;

  // (1, log2(triangles + 1), density_spread, flatness, log2(1 + area_ratio)).
  std::array<double, kFeatureCount> regressors() const;
};

// Bounds from every triangle; cells and area from an even sample of at most
// about 2 x kSampledTriangles (every (N / kSampledTriangles)-th triangle,
// the area scaled up), so that choosing costs little next to the cheapest
// build. Empty input gives zeros.
inline constexpr std::size_t kSampledTriangles = 2048;
BrickFeatures measure_brick_features(std::span<const Triangle> triangles);

}  // namespace outcore
