#include "core/accel/hgrid/hierarchical_grid.h"

#include <string>
#include <utility>

#include "core/accel/triangle_hit_records.h"

namespace outcore {

Status HierarchicalGridView::validate() const {
  OUTCORE_RETURN_IF_ERROR(validate_triangle_refs("hgrid", refs, triangles, records));
  if (grids.empty()) {
    if (!cells.empty() || !refs.empty() || !triangles.empty()) {
      return invalid_argument("hgrid: triangles without a grid");
    }
    return Status::Ok();
  }
  // Every grid valid, its cells right after the previous grid's (so each
  // cell belongs to exactly one grid).
  uint64_t next_cell = 0;
  for (std::size_t g = 0; g < grids.size(); ++g) {
    const std::string what = "hgrid grid " + std::to_string(g);
    if (grids[g].first_cell != next_cell) {
      return invalid_argument(what + ": its cells start at " + std::to_string(grids[g].first_cell) +
                              ", not " + std::to_string(next_cell));
    }
    OUTCORE_RETURN_IF_ERROR(grids[g].lattice().validate(what, kMaxHgridResolution, kMaxHgridCells));
    next_cell += grids[g].cell_count();
  }
  if (next_cell != cells.size()) {
    return invalid_argument("hgrid: " + std::to_string(cells.size()) + " cells for the grids' " +
                            std::to_string(next_cell));
  }
  // From the root down: every other grid nested in exactly one cell of a
  // grid before it, within kMaxHgridLevels; reference runs within refs.
  std::vector<uint8_t> level(grids.size(), 0);
  level[0] = 1;
  for (std::size_t g = 0; g < grids.size(); ++g) {
    if (level[g] == 0) return invalid_argument("hgrid: grid " + std::to_string(g) + " is in no cell");
    const uint64_t first = grids[g].first_cell;
    for (uint64_t c = first; c < first + grids[g].cell_count(); ++c) {
      const HgridCell& cell = cells[c];
      if (!cell.is_nested()) {
        if (uint64_t{cell.first} + cell.count() > refs.size()) {
          return invalid_argument("hgrid: cell " + std::to_string(c) + " reaches past the " +
                                  std::to_string(refs.size()) + " references");
        }
        continue;
      }
      const uint32_t child = cell.grid();
      if (child <= g || child >= grids.size() || level[child] != 0 || level[g] >= kMaxHgridLevels) {
        return invalid_argument("hgrid: cell " + std::to_string(c) + " of grid " + std::to_string(g) +
                                " nests grid " + std::to_string(child) + " of " +
                                std::to_string(grids.size()) + " (each once, after its parent, within " +
                                std::to_string(kMaxHgridLevels) + " levels)");
      }
      level[child] = static_cast<uint8_t>(level[g] + 1);
    }
  }
  return Status::Ok();
}

}  // namespace outcore
