#include "core/accel/grid/uniform_grid_builder.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <utility>

#include "core/accel/triangle_hit_records.h"
#include "core/geometry/triangle_box_overlap.h"
#include "core/util/parse_number.h"

namespace outcore {
namespace {

uint64_t cells_cap(uint64_t n) {
  return UniformGridBuilder::kMaxCellsPerTriangle * n + 4096;
}
uint64_t references_cap(uint64_t n) {
  return UniformGridBuilder::kMaxReferencesPerTriangle * n + 64;
}

uint64_t product(const std::array<uint32_t, 3>& r) {
  return uint64_t{r[0]} * r[1] * r[2];
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

// Halves every axis (down to one cell).
void coarsen(std::array<uint32_t, 3>& resolution) {
  for (uint32_t& r : resolution) r = std::max<uint32_t>(1, (r + 1) / 2);
}

struct CellPair {
  uint32_t cell;
  uint32_t triangle;
};

// The (cell, triangle) pairs of every triangle at `grid`'s resolution, in
// triangle order; false when they exceed `cap` (the caller coarsens).
bool file_triangles(const UniformGridView& grid, std::span<const Triangle> triangles, uint64_t cap,
                    std::vector<CellPair>& pairs) {
  pairs.clear();
  const double box_margin = cell_filing_margin(grid.bounds, Vec3d(grid.cell_width));
  const uint32_t rx = grid.resolution[0], ry = grid.resolution[1];
  auto cell_lo = [&](int a, uint32_t j) { return j == 0 ? grid.bounds.lo[a] : grid.boundary(a, j); };
  auto cell_hi = [&](int a, uint32_t j) {
    return j + 1 == grid.resolution[a] ? grid.bounds.hi[a] : grid.boundary(a, j + 1);
  };
  for (uint32_t k = 0; k < triangles.size(); ++k) {
    const Aabb box = triangles[k].bounds();
    std::array<uint32_t, 3> first{}, last{};
    for (int a = 0; a < 3; ++a) {
      first[a] = grid.lowest_cell_holding(a, box.lo[a]);
      last[a] = grid.highest_cell_holding(a, box.hi[a]);
    }
    // A triangle is connected, so its projection on an axis covers every
    // cell its bounds span there: when its bounds span one row of cells (at
    // most one axis with more than one), it touches all of them.
    const int spread_axes = (first[0] != last[0]) + (first[1] != last[1]) + (first[2] != last[2]);
    const bool test_each_cell = spread_axes > 1;
    for (uint32_t z = first[2]; z <= last[2]; ++z) {
      for (uint32_t y = first[1]; y <= last[1]; ++y) {
        for (uint32_t x = first[0]; x <= last[0]; ++x) {
          if (test_each_cell) {
            const Vec3d lo(cell_lo(0, x), cell_lo(1, y), cell_lo(2, z));
            const Vec3d hi(cell_hi(0, x), cell_hi(1, y), cell_hi(2, z));
            if (!triangle_may_touch_box(triangles[k], lo, hi, box_margin)) continue;
          }
          if (pairs.size() >= cap) return false;
          pairs.push_back({x + rx * (y + ry * z), k});
        }
      }
    }
  }
  return true;
}

}  // namespace

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
  while (product(resolution) > cells_cap(n)) coarsen(resolution);
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
    for (int a = 0; a < 3; ++a) {
      grid.cell_width[a] = (grid.bounds.hi[a] - grid.bounds.lo[a]) / static_cast<float>(grid.resolution[a]);
    }
    if (file_triangles(grid.view(), grid.triangles, references_cap(n), pairs)) break;
    assert(product(grid.resolution) > 1);  // one cell holds each triangle once
    coarsen(grid.resolution);
  }
  result.peak_bytes = pairs.capacity() * sizeof(CellPair);

  // Counting sort of the pairs by cell; within a cell, triangle order.
  grid.cell_starts.assign(product(grid.resolution) + 1, 0);
  for (const CellPair& pair : pairs) ++grid.cell_starts[pair.cell + 1];
  for (std::size_t c = 1; c < grid.cell_starts.size(); ++c) grid.cell_starts[c] += grid.cell_starts[c - 1];
  grid.refs.resize(pairs.size());
  std::vector<uint32_t> next(grid.cell_starts.begin(), grid.cell_starts.end() - 1);
  for (const CellPair& pair : pairs) grid.refs[next[pair.cell]++] = pair.triangle;
  result.peak_bytes += next.capacity() * sizeof(uint32_t);
  // Exact capacities: memory_bytes() then equals a reloaded grid's.
  grid.triangles.shrink_to_fit();
  return result;
}

}  // namespace outcore
