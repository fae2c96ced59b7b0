#include "core/accel/grid/grid_filing.h"

#include <array>
#include <cmath>
#include <optional>

#include "core/geometry/triangle_box_overlap.h"

namespace outcore {
namespace {

// The cell a coordinate falls in along each axis, guessed by a product with
// the inverse cell width (a division per coordinate was a fifth of a grid's
// build); GridLattice's exact comparisons then settle it.
class CellGuess {
 public:
  explicit CellGuess(const GridLattice& lattice) {
    for (int a = 0; a < 3; ++a) {
      lo_[a] = lattice.bounds.lo[a];
      inverse_width_[a] = 1.0 / double{lattice.cell_width[a]};
      last_[a] = lattice.resolution[a] - 1;
    }
  }
  uint32_t operator()(int axis, float x) const {
    const double guess = std::floor((double{x} - lo_[axis]) * inverse_width_[axis]);
    if (!(guess > 0)) return 0;  // also NaN (zero width)
    return guess >= last_[axis] ? last_[axis] : static_cast<uint32_t>(guess);
  }

 private:
  double lo_[3], inverse_width_[3];
  uint32_t last_[3];
};

}  // namespace

bool file_triangles(const GridLattice& lattice, std::span<const Triangle> triangles,
                    std::span<const uint32_t> which, uint64_t cap, std::vector<CellPair>& pairs) {
  const double box_margin = cell_filing_margin(lattice.bounds, Vec3d(lattice.cell_width));
  const CellGuess guess(lattice);
  const std::size_t count = which.empty() ? triangles.size() : which.size();
  for (std::size_t i = 0; i < count; ++i) {
    const uint32_t k = which.empty() ? static_cast<uint32_t>(i) : which[i];
    const Aabb box = triangles[k].bounds();
    std::array<uint32_t, 3> first{}, last{};
    for (int a = 0; a < 3; ++a) {
      first[a] = lattice.lowest_cell_holding_from(a, box.lo[a], guess(a, box.lo[a]));
      last[a] = lattice.highest_cell_holding_from(a, box.hi[a], guess(a, box.hi[a]));
    }
    const int spread_axes = (first[0] != last[0]) + (first[1] != last[1]) + (first[2] != last[2]);
    const bool test_each_cell = spread_axes > 1;
    std::optional<TrianglePlaneOverlap> overlap;
    if (test_each_cell) overlap.emplace(triangles[k]);
    for (uint32_t z = first[2]; z <= last[2]; ++z) {
      for (uint32_t y = first[1]; y <= last[1]; ++y) {
        for (uint32_t x = first[0]; x <= last[0]; ++x) {
          if (test_each_cell) {
            const Aabb cell = lattice.cell_box(x, y, z);
            if (!overlap->plane_may_touch_box(Vec3d(cell.lo), Vec3d(cell.hi), box_margin)) continue;
          }
          if (pairs.size() >= cap) return false;
          pairs.push_back({lattice.cell_index(x, y, z), k});
        }
      }
    }
  }
  return true;
}

uint64_t append_cells(std::span<const CellPair> pairs, uint64_t cell_count,
                      std::vector<uint32_t>& cell_starts, std::vector<uint32_t>& refs) {
  const std::size_t base = cell_starts.size();
  cell_starts.resize(base + cell_count, 0);
  uint32_t* starts = cell_starts.data() + base;
  for (const CellPair& pair : pairs) ++starts[pair.cell];
  uint32_t running = static_cast<uint32_t>(refs.size());
  for (uint64_t c = 0; c < cell_count; ++c) {
    const uint32_t count = starts[c];
    starts[c] = running;
    running += count;
  }
  refs.resize(running);
  std::vector<uint32_t> next(starts, starts + cell_count);
  for (const CellPair& pair : pairs) refs[next[pair.cell]++] = pair.triangle;
  return next.capacity() * sizeof(uint32_t);
}

}  // namespace outcore
