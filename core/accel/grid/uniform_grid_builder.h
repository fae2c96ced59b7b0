// UniformGridBuilder: a UniformGrid over a brick's triangles in linear time
// (Lagae & Dutré 2008): the resolution from a rule, every triangle filed
// under the cells it may touch (grid_filing.h), then one counting sort of the (cell, triangle) pairs into the
// compact arrays. Within a cell, triangles keep their input order.
//
// Resolution rules (Config::rule):
// - density: about cells_per_triangle * N cells shaped like the bounds,
//   resolution[a] = extent[a] * cbrt(cells_per_triangle * N / volume)
//   (Cleary & Wyvill; Lagae & Dutré's lambda), an axis too thin for one cell
//   taking one and the others sharing the cells, so flat bricks get a 2D
//   grid;
// - pbrt: 3 * cbrt(N) cells along the longest axis, the others in proportion
//   (pbrt-v1's GridAccel).
// Either is capped at max_resolution per axis, at kMaxCellsPerTriangle * N +
// 4096 cells, and, when the triangles would need more than
// kMaxReferencesPerTriangle references each on average (large triangles in
// small cells), halved until they fit: that bounds memory for the cache's
// reservation.
//
// Thread-safety: build() is reentrant (no shared state).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/accel/grid/uniform_grid.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

class UniformGridBuilder {
 public:
  enum class ResolutionRule { kDensity, kPbrt };

  struct Config {
    ResolutionRule rule = ResolutionRule::kDensity;
    float cells_per_triangle = 2.0f;  // lambda of the density rule
    uint32_t max_resolution = 512;    // per axis

    Status validate() const;
    // Sets the option `key` (resolution, cells_per_triangle,
    // max_resolution) from `value`: false when `key` is none of them, an
    // error naming `structure` when the value is malformed.
    Expected<bool> parse_option(std::string_view structure, const std::string& key, const std::string& value);
  };

  static constexpr uint64_t kMaxReferencesPerTriangle = 8;
  static constexpr uint64_t kMaxCellsPerTriangle = 16;
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 24;

  struct Result {
    UniformGrid tree;
    uint64_t peak_bytes = 0;  // the build's own scratch at its largest (the pairs)
  };

  // triangles: usable ones (finite, not degenerate); ids[k] belongs to
  // triangles[k]. The grid keeps them in this order.
  static Result build(std::vector<Triangle> triangles, const std::vector<TriangleId>& ids,
                      const Config& config);

  // The resolution a build of n triangles within `bounds` starts from.
  static std::array<uint32_t, 3> resolution_for(const Aabb& bounds, uint64_t n, const Config& config);

  // Halves every axis (down to one cell).
  static void coarsen(std::array<uint32_t, 3>& resolution);

  // Upper bounds, for n triangles: the grid's arrays, and the build's peak
  // scratch.
  static uint64_t tree_bytes_bound(uint64_t n);
  static uint64_t peak_bytes_bound(uint64_t n);
};

std::string_view resolution_rule_name(UniformGridBuilder::ResolutionRule rule);

}  // namespace outcore
