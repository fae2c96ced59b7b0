#include "core/accel/grid/uniform_grid.h"

#include <string>

#include "core/accel/triangle_hit_records.h"

namespace outcore {

namespace {

// Non-empty cell starts run from 0 to the references without going back.
Status validate_cell_starts(const std::string& what, std::span<const uint32_t> cell_starts,
                            std::size_t reference_count) {
  if (cell_starts.front() != 0 || cell_starts.back() != reference_count) {
    return invalid_argument(what + ": cell starts run from " + std::to_string(cell_starts.front()) + " to " +
                            std::to_string(cell_starts.back()) + ", not 0 to the " +
                            std::to_string(reference_count) + " references");
  }
  for (std::size_t c = 0; c + 1 < cell_starts.size(); ++c) {
    if (cell_starts[c] > cell_starts[c + 1]) {
      return invalid_argument(what + ": cell " + std::to_string(c) + " ends before it starts");
    }
  }
  return Status::Ok();
}

}  // namespace

Status UniformGridView::validate() const {
  OUTCORE_RETURN_IF_ERROR(validate_triangle_refs("grid", refs, triangles, records));
  if (cell_starts.empty()) {
    if (!refs.empty() || !triangles.empty()) return invalid_argument("grid: triangles without cells");
    return Status::Ok();
  }
  OUTCORE_RETURN_IF_ERROR(GridLattice::validate("grid", kMaxGridResolution, kMaxGridCells));
  if (cell_starts.size() != cell_count() + 1) {
    return invalid_argument("grid: " + std::to_string(cell_starts.size()) + " cell starts for " +
                            std::to_string(cell_count()) + " cells");
  }
  return validate_cell_starts("grid", cell_starts, refs.size());
}

}  // namespace outcore
