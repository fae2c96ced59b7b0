#include "core/accel/grid/uniform_grid.h"

#include <cmath>
#include <string>

namespace outcore {
namespace {

// A first guess from the cell width, then exact comparisons with the
// boundaries (the guess may be off by one where rounding differs).
uint32_t guess_cell(const UniformGridView& grid, int axis, float x) {
  const uint32_t last = grid.resolution[axis] - 1;
  const double guess = std::floor((double{x} - grid.bounds.lo[axis]) / grid.cell_width[axis]);
  if (!(guess > 0)) return 0;  // also NaN (zero width)
  return guess >= last ? last : static_cast<uint32_t>(guess);
}

}  // namespace

uint32_t UniformGridView::lowest_cell_holding(int axis, float x) const {
  uint32_t cell = guess_cell(*this, axis, x);
  // Cell j holds x when boundary(j) <= x <= boundary(j + 1).
  while (cell > 0 && boundary(axis, cell) >= x) --cell;
  while (cell + 1 < resolution[axis] && boundary(axis, cell + 1) < x) ++cell;
  return cell;
}

uint32_t UniformGridView::highest_cell_holding(int axis, float x) const {
  uint32_t cell = guess_cell(*this, axis, x);
  while (cell + 1 < resolution[axis] && boundary(axis, cell + 1) <= x) ++cell;
  while (cell > 0 && boundary(axis, cell) > x) --cell;
  return cell;
}

Status UniformGridView::validate() const {
  if (records.size() != triangles.size()) {
    return invalid_argument("grid: " + std::to_string(records.size()) + " hit records for " +
                            std::to_string(triangles.size()) + " triangles");
  }
  for (std::size_t k = 0; k < refs.size(); ++k) {
    if (refs[k] >= triangles.size()) {
      return invalid_argument("grid: reference " + std::to_string(k) + " names triangle " +
                              std::to_string(refs[k]) + " of " + std::to_string(triangles.size()));
    }
  }
  if (cell_starts.empty()) {
    if (!refs.empty() || !triangles.empty()) return invalid_argument("grid: triangles without cells");
    return Status::Ok();
  }
  for (int axis = 0; axis < 3; ++axis) {
    if (resolution[axis] < 1 || resolution[axis] > kMaxGridResolution) {
      return invalid_argument("grid: resolution " + std::to_string(resolution[axis]) + " along axis " +
                              std::to_string(axis) + " (1 .. " + std::to_string(kMaxGridResolution) + ")");
    }
    const float lo = bounds.lo[axis], hi = bounds.hi[axis], width = cell_width[axis];
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo <= hi) || !std::isfinite(width) || width < 0) {
      return invalid_argument("grid: bounds or cell width along axis " + std::to_string(axis) +
                              " are not finite and ordered");
    }
  }
  if (cell_count() > kMaxGridCells || cell_starts.size() != cell_count() + 1) {
    return invalid_argument("grid: " + std::to_string(cell_starts.size()) + " cell starts for " +
                            std::to_string(cell_count()) + " cells");
  }
  if (cell_starts.front() != 0 || cell_starts.back() != refs.size()) {
    return invalid_argument("grid: cell starts run from " + std::to_string(cell_starts.front()) + " to " +
                            std::to_string(cell_starts.back()) + ", not 0 to the " +
                            std::to_string(refs.size()) + " references");
  }
  for (std::size_t c = 0; c + 1 < cell_starts.size(); ++c) {
    if (cell_starts[c] > cell_starts[c + 1]) {
      return invalid_argument("grid: cell " + std::to_string(c) + " ends before it starts");
    }
  }
  return Status::Ok();
}

}  // namespace outcore
