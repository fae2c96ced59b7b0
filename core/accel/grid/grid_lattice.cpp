#include "core/accel/grid/grid_lattice.h"

#include <cmath>

namespace outcore {
namespace {

// A first guess from the cell width, then exact comparisons with the
// boundaries (the guess may be off by one where rounding differs).
uint32_t guess_cell(const GridLattice& grid, int axis, float x) {
  const uint32_t last = grid.resolution[axis] - 1;
  const double guess = std::floor((double{x} - grid.bounds.lo[axis]) / grid.cell_width[axis]);
  if (!(guess > 0)) return 0;  // also NaN (zero width)
  return guess >= last ? last : static_cast<uint32_t>(guess);
}

}  // namespace

uint32_t GridLattice::lowest_cell_holding(int axis, float x) const {
  return lowest_cell_holding_from(axis, x, guess_cell(*this, axis, x));
}

uint32_t GridLattice::highest_cell_holding(int axis, float x) const {
  return highest_cell_holding_from(axis, x, guess_cell(*this, axis, x));
}

Status GridLattice::validate(const std::string& what, uint32_t max_resolution, uint64_t max_cells) const {
  for (int axis = 0; axis < 3; ++axis) {
    if (resolution[axis] < 1 || resolution[axis] > max_resolution) {
      return invalid_argument(what + ": resolution " + std::to_string(resolution[axis]) + " along axis " +
                              std::to_string(axis) + " (1 .. " + std::to_string(max_resolution) + ")");
    }
    const float lo = bounds.lo[axis], hi = bounds.hi[axis], width = cell_width[axis];
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo <= hi) || !std::isfinite(width) || width < 0) {
      return invalid_argument(what + ": bounds or cell width along axis " + std::to_string(axis) +
                              " are not finite and ordered");
    }
  }
  if (cell_count() > max_cells) {
    return invalid_argument(what + ": " + std::to_string(cell_count()) + " cells, more than " +
                            std::to_string(max_cells));
  }
  return Status::Ok();
}

}  // namespace outcore
