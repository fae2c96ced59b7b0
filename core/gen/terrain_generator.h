// TerrainGenerator (`gen:terrain`): a flat, wide fractal heightfield: an n x n
// grid of cells over [-size/2, size/2]^2 in x/z, two triangles per cell
// (2 * n^2), heights in y from hash-based value-noise fBm.
//
// The height of grid vertex (i, j) is a pure function of (i, j, seed, n,
// octaves), so the grid is never stored and neighbouring cells share
// bit-identical vertices. Triangles are emitted row by row (row j = z index,
// cell i = x index, id = 2 * (j * n + i) + {0, 1}), wound counter-clockwise
// seen from above (+y normals). Memory: two rows of vertices, O(n) (< 1.5 MB).
//
// Parameters: n (cells per side, 1..46340, default 256), size (> 0, default
// 1000), height (amplitude, >= 0, default 50), octaves (1..16, default 6), seed
// (0..2^63-1, default 1).
//
// Thread-safety: see Generator (emit() is const and stateless).
#pragma once

#include <memory>

#include "core/gen/gen_spec.h"
#include "core/gen/generator.h"

namespace outcore {

struct TerrainConfig {
  int n = 256;           // cells per side: 2 * n^2 triangles
  double size = 1000.0;  // horizontal extent, centred on the origin in x and z
  double height = 50.0;  // heights lie in [-height, height]
  int octaves = 6;       // fBm octaves; octave o has 4 * 2^o noise cells per side
  int64_t seed = 1;

  // 2 * 46340^2 < 2^32 - 1: every primitive id fits in uint32.
  static constexpr int kMaxN = 46340;
  static Expected<TerrainConfig> parse(const GenSpec& spec);
};

class TerrainGenerator final : public Generator {
 public:
  TerrainGenerator(std::string description, const TerrainConfig& config);
  static Expected<std::unique_ptr<TerrainGenerator>> create(const GenSpec& spec);

  const TerrainConfig& config() const { return config_; }
  uint64_t triangle_count() const override {
    return 2ull * static_cast<uint64_t>(config_.n) * static_cast<uint64_t>(config_.n);
  }
  Status emit(TriangleBatcher& out) const override;
  // By rows of 2n triangles: a range computes only the rows it touches.
  Status emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const override;
  bool has_fast_ranges() const override { return true; }
  uint64_t range_granularity() const override { return 2 * static_cast<uint64_t>(config_.n); }

  // Height (y) of grid vertex (i, j), 0 <= i, j <= n; the emitted vertices use
  // exactly this value (rounded to float).
  double height_at(int i, int j) const;

 private:
  // Heights of grid row j (vertices i = 0..n) into `row` (size n + 1).
  void height_row(int j, std::vector<double>& row) const;

  TerrainConfig config_;
};

}  // namespace outcore
