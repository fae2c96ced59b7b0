#include "core/accel/grid/uniform_grid_builder.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <utility>

#include "core/accel/grid/grid_filing.h"
#include "core/accel/triangle_hit_records.h"
#include "core/util/parse_number.h"

namespace outcore {
namespace {

uint64_t cells_cap(uint64_t n) {
  return UniformGridBuilder::kMaxCellsPerTriangle * n + 4096;
}
uint64_t references_cap(uint64_t n) {
  return UniformGridBuilder::kMaxReferencesPerTriangle * n + 64;
}

uint32_t clamp_cells(double cells, uint32_t max_resolution) {
  if (!(cells >= 1.0)) return 1;
  return static_cast<uint32_t>(std::min<double>(std::lround(cells), max_resolution));
}

std::array<uint32_t, 3> density_resolution(const Vec3d& extent, uint64_t n,
                                           const UniformGridBuilder::Config& config) {
  const double target = static_cast<double>(config.cells_per_triangle) * static_cast<double>(n);
  std::array<uint32_t, 3> resolution{1, 1, 1};
  // Axes still sharing the cells; one too thin for a cell takes one and the
  // rest are recomputed without it.
  std::array<bool, 3> shared{extent.x > 0, extent.y > 0, extent.z > 0};
  for (int round = 0; round < 3; ++round) {
    int dims = 0;
    double volume = 1.0;
    for (int a = 0; a < 3; ++a) {
      if (!shared[a]) continue;
      ++dims;
      volume *= extent[a];
    }
    if (dims == 0) break;
    const double per_unit = std::pow(target / volume, 1.0 / dims);
    bool dropped = false;
    for (int a = 0; a < 3; ++a) {
      if (shared[a] && extent[a] * per_unit < 1.0) {
        shared[a] = false;
        dropped = true;
      }
    }
    if (dropped) continue;
    for (int a = 0; a < 3; ++a) {
      if (shared[a]) resolution[a] = clamp_cells(extent[a] * per_unit, config.max_resolution);
    }
    break;
  }
  return resolution;
}

std::array<uint32_t, 3> pbrt_resolution(const Vec3d& extent, uint64_t n,
                                        const UniformGridBuilder::Config& config) {
  const double longest = std::max({extent.x, extent.y, extent.z});
  std::array<uint32_t, 3> resolution{1, 1, 1};
  if (!(longest > 0)) return resolution;
  const double per_unit = 3.0 * std::cbrt(static_cast<double>(n)) / longest;
  for (int a = 0; a < 3; ++a) resolution[a] = clamp_cells(extent[a] * per_unit, config.max_resolution);
  return resolution;
}

}  // namespace

void UniformGridBuilder::coarsen(std::array<uint32_t, 3>& resolution) {
  for (uint32_t& r : resolution) r = std::max<uint32_t>(1, (r + 1) / 2);
}

std::string_view resolution_rule_name(UniformGridBuilder::ResolutionRule rule) {
  return rule == UniformGridBuilder::ResolutionRule::kPbrt ? "pbrt" : "density";
}

Status UniformGridBuilder::Config::validate() const {
  if (!(cells_per_triangle > 0.0f && cells_per_triangle <= static_cast<float>(kMaxCellsPerTriangle))) {
    return invalid_argument("grid: cells_per_triangle must be in (0, " +
                            std::to_string(kMaxCellsPerTriangle) + "], got " +
                            std::to_string(cells_per_triangle));
  }
  if (max_resolution < 1 || max_resolution > kMaxGridResolution) {
    return invalid_argument("grid: max_resolution must be in [1, " + std::to_string(kMaxGridResolution) +
                            "], got " + std::to_string(max_resolution));
  }
  return Status::Ok();
}

Expected<bool> UniformGridBuilder::Config::parse_option(std::string_view structure, const std::string& key,
                                                        const std::string& value) {
  const std::string what = "brick accel " + std::string(structure) + ": option " + key;
  if (key == "resolution") {
    if (value == "density") {
      rule = ResolutionRule::kDensity;
    } else if (value == "pbrt") {
      rule = ResolutionRule::kPbrt;
    } else {
      return invalid_argument(what + " must be density or pbrt, got '" + value + "'");
    }
    return true;
  }
  if (key == "cells_per_triangle") {
    if (!parse_number(value, cells_per_triangle) || !std::isfinite(cells_per_triangle))
      return invalid_argument(what + " must be a number, got '" + value + "'");
    return true;
  }
  if (key == "max_resolution") {
    if (!parse_number(value, max_resolution))
      return invalid_argument(what + " must be a whole number, got '" + value + "'");
    return true;
  }
  return false;
}

std::array<uint32_t, 3> UniformGridBuilder::resolution_for(const Aabb& bounds, uint64_t n,
                                                           const Config& config) {
  const Vec3d extent(bounds.extent());
  std::array<uint32_t, 3> resolution = config.rule == ResolutionRule::kPbrt
                                           ? pbrt_resolution(extent, n, config)
                                           : density_resolution(extent, n, config);
  while (cell_count_of(resolution) > cells_cap(n)) coarsen(resolution);
  return resolution;
}

uint64_t UniformGridBuilder::tree_bytes_bound(uint64_t n) {
  return (cells_cap(n) + 1 + references_cap(n)) * sizeof(uint32_t) +
         n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// The pairs, and the counting sort's next free slot per cell.
uint64_t UniformGridBuilder::peak_bytes_bound(uint64_t n) {
  return references_cap(n) * sizeof(CellPair) + (cells_cap(n) + 1) * sizeof(uint32_t);
}

UniformGridBuilder::Result UniformGridBuilder::build(std::vector<Triangle> triangles,
                                                     const std::vector<TriangleId>& ids,
                                                     const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  UniformGrid& grid = result.tree;
  if (triangles.empty()) return result;
  const uint64_t n = triangles.size();
  for (const Triangle& tri : triangles) grid.bounds.extend(tri.bounds());
  grid.records = hit_records_for(triangles, ids);
  grid.triangles = std::move(triangles);

  std::vector<CellPair> pairs;
  pairs.reserve(2 * n);
  grid.resolution = resolution_for(grid.bounds, n, config);
  while (true) {
    static_cast<GridLattice&>(grid) = GridLattice::over(grid.bounds, grid.resolution);
    pairs.clear();
    if (file_triangles(grid, grid.triangles, {}, references_cap(n), pairs)) break;
    assert(cell_count_of(grid.resolution) > 1);  // one cell holds each triangle once
    coarsen(grid.resolution);
  }
  result.peak_bytes = pairs.capacity() * sizeof(CellPair);
  grid.cell_starts.reserve(cell_count_of(grid.resolution) + 1);
  result.peak_bytes += append_cells(pairs, cell_count_of(grid.resolution), grid.cell_starts, grid.refs);
  grid.cell_starts.push_back(static_cast<uint32_t>(grid.refs.size()));
  // Exact capacities: memory_bytes() then equals a reloaded grid's.
  grid.refs.shrink_to_fit();
  grid.triangles.shrink_to_fit();
  return result;
}

}  // namespace outcore
