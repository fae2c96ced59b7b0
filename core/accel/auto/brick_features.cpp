#include "core/accel/auto/brick_features.h"

#include <algorithm>
#include <cmath>

namespace outcore {
namespace {

constexpr int kCellsPerAxis = 4;
constexpr int kCells = kCellsPerAxis * kCellsPerAxis * kCellsPerAxis;

float cells_per_unit(float extent) {
  return extent > 0 ? kCellsPerAxis / extent : 0.0f;
}

// Clamped before the conversion, so that a non-finite value is cell 0, not
// undefined behaviour.
int cell_along(float value, float lo, float cells_per_unit) {
  const float cell = (value - lo) * cells_per_unit;
  if (!(cell >= 1.0f)) return 0;
  return cell >= kCellsPerAxis - 1 ? kCellsPerAxis - 1 : static_cast<int>(cell);
}

}  // namespace

std::array<double, kFeatureCount> BrickFeatures::regressors() const {
  return {1.0, std::log2(static_cast<double>(triangles) + 1.0), density_spread, flatness,
          std::log2(1.0 + area_ratio)};
}

BrickFeatures measure_brick_features(std::span<const Triangle> triangles) {
  BrickFeatures features;
  features.triangles = static_cast<uint32_t>(triangles.size());
  if (triangles.empty()) return features;
  Aabb bounds;
  for (const Triangle& t : triangles) bounds.extend(t.bounds());
  const Vec3f extent = bounds.extent();
  const float widest = std::max({extent.x, extent.y, extent.z});
  const float thinnest = std::min({extent.x, extent.y, extent.z});
  features.flatness = widest > 0 ? static_cast<double>(thinnest) / widest : 1.0;

  // Cells and area from an even sample: they are shares, and the choice
  // they feed must cost little next to the cheapest build (a grid's, a few
  // ns a triangle).
  const std::size_t stride = std::max<std::size_t>(1, triangles.size() / kSampledTriangles);
  std::array<uint32_t, kCells> counts{};
  double area = 0;
  std::size_t sampled = 0;
  const Vec3f to_cell{cells_per_unit(extent.x), cells_per_unit(extent.y), cells_per_unit(extent.z)};
  for (std::size_t i = 0; i < triangles.size(); i += stride, ++sampled) {
    const Triangle& t = triangles[i];
    const Vec3f c = t.centroid();
    const int x = cell_along(c.x, bounds.lo.x, to_cell.x);
    const int y = cell_along(c.y, bounds.lo.y, to_cell.y);
    const int z = cell_along(c.z, bounds.lo.z, to_cell.z);
    ++counts[static_cast<std::size_t>((z * kCellsPerAxis + y) * kCellsPerAxis + x)];
    const Vec3d a(t.v0), b(t.v1), d(t.v2);
    const Vec3d n = cross(b - a, d - a);
    const double twice = std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
    if (std::isfinite(twice)) area += 0.5 * twice;
  }
  area *= static_cast<double>(triangles.size()) / static_cast<double>(sampled);
  const uint32_t fullest = *std::max_element(counts.begin(), counts.end());
  features.density_spread = std::log2(static_cast<double>(fullest) * kCells / static_cast<double>(sampled));
  const double surface = 2.0 * bounds.half_area();
  features.area_ratio = surface > 0 && std::isfinite(surface) ? area / surface : 0.0;
  return features;
}

}  // namespace outcore
