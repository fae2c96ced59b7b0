#include "core/gen/terrain_generator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/gen/splitmix.h"

namespace outcore {

namespace {

constexpr double kBaseFrequency = 4.0;  // noise cells per side in octave 0

// Lattice value in [-1, 1) of noise cell corner (ix, iz) for one octave's key.
double lattice(uint64_t octave_key, int64_t ix, int64_t iz) {
  const uint64_t h = mix64(mix64(octave_key ^ static_cast<uint64_t>(ix)) ^ static_cast<uint64_t>(iz));
  return static_cast<double>(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

double fade(double t) {
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}  // quintic
double lerp(double a, double b, double t) {
  return a + (b - a) * t;
}

uint64_t octave_key(int64_t seed, int octave) {
  return mix64(static_cast<uint64_t>(seed) * 0x9e3779b97f4a7c15ull + static_cast<uint64_t>(octave) + 1);
}

// Octave o's lattice coordinate of grid index k: k * f / n, computed the same
// way for rows and columns.
double lattice_coord(int k, double frequency, int n) {
  return static_cast<double>(k) * frequency / static_cast<double>(n);
}

}  // namespace

Expected<TerrainConfig> TerrainConfig::parse(const GenSpec& spec) {
  TerrainConfig c;
  GenParams p(spec);
  p.integer("n", c.n, 1, kMaxN);
  p.real("size", c.size, RealRange::positive());
  p.real("height", c.height, RealRange::closed(0.0, RealRange::kLimit));
  p.integer("octaves", c.octaves, 1, 16);
  p.integer("seed", c.seed, 0, std::numeric_limits<int64_t>::max());
  OUTCORE_RETURN_IF_ERROR(p.finish());
  return c;
}

TerrainGenerator::TerrainGenerator(std::string description, const TerrainConfig& config)
    : Generator(std::move(description)), config_(config) {}

Expected<std::unique_ptr<TerrainGenerator>> TerrainGenerator::create(const GenSpec& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const TerrainConfig config, TerrainConfig::parse(spec));
  return std::make_unique<TerrainGenerator>(spec.text, config);
}

void TerrainGenerator::height_row(int j, std::vector<double>& row) const {
  const TerrainConfig& c = config_;
  row.assign(static_cast<std::size_t>(c.n) + 1, 0.0);
  double amplitude = 1.0, total = 0.0;
  for (int o = 0; o < c.octaves; ++o) {
    const uint64_t key = octave_key(c.seed, o);
    const double frequency = std::ldexp(kBaseFrequency, o);
    const double z = lattice_coord(j, frequency, c.n);
    const double zf = std::floor(z);
    const auto iz = static_cast<int64_t>(zf);
    const double fz = fade(z - zf);
    // Noise along the row, interpolated in z first; lattice columns are cached
    // while consecutive vertices fall in the same noise cell.
    int64_t cached_ix = std::numeric_limits<int64_t>::min();
    double col0 = 0, col1 = 0;
    for (int i = 0; i <= c.n; ++i) {
      const double x = lattice_coord(i, frequency, c.n);
      const double xf = std::floor(x);
      const auto ix = static_cast<int64_t>(xf);
      if (ix != cached_ix) {
        col0 = lerp(lattice(key, ix, iz), lattice(key, ix, iz + 1), fz);
        col1 = lerp(lattice(key, ix + 1, iz), lattice(key, ix + 1, iz + 1), fz);
        cached_ix = ix;
      }
      row[static_cast<std::size_t>(i)] += amplitude * lerp(col0, col1, fade(x - xf));
    }
    total += amplitude;
    amplitude *= 0.5;
  }
  const double scale = c.height / total;
  for (double& h : row) h *= scale;
}

double TerrainGenerator::height_at(int i, int j) const {
  std::vector<double> row;
  height_row(j, row);
  return row[static_cast<std::size_t>(i)];
}

Status TerrainGenerator::emit(TriangleBatcher& out) const {
  return emit_range(0, triangle_count(), out);
}

Status TerrainGenerator::emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const {
  const TerrainConfig& c = config_;
  last = std::min(last, triangle_count());
  if (first >= last) return Status::Ok();
  const auto n = static_cast<std::size_t>(c.n);
  const uint64_t per_row = 2 * static_cast<uint64_t>(n);
  const auto coord = [&](int k) {
    return (static_cast<double>(k) / static_cast<double>(c.n) - 0.5) * c.size;
  };
  std::vector<double> heights;
  std::vector<Vec3f> lower(n + 1), upper(n + 1);
  const auto make_row = [&](int j, std::vector<Vec3f>& row) {
    height_row(j, heights);
    const double z = coord(j);
    for (std::size_t i = 0; i <= n; ++i) row[i] = to_vertex(Vec3d(coord(static_cast<int>(i)), heights[i], z));
  };
  const int first_row = static_cast<int>(first / per_row);
  make_row(first_row, lower);
  for (int j = first_row; static_cast<uint64_t>(j) * per_row < last; ++j) {
    make_row(j + 1, upper);
    const uint64_t row_start = static_cast<uint64_t>(j) * per_row;
    const uint64_t begin = std::max(first, row_start) - row_start,
                   end = std::min(last, row_start + per_row) - row_start;
    for (uint64_t k = begin; k < end; ++k) {
      // p00 = (i, j), p10 = (i+1, j), p01 = (i, j+1), p11 = (i+1, j+1), i along x and
      // j along z: cross(p01 - p00, p11 - p00) ~ z x x = +y, so both are +y facing.
      const std::size_t i = static_cast<std::size_t>(k / 2);
      const Vec3f p00 = lower[i], p10 = lower[i + 1], p01 = upper[i], p11 = upper[i + 1];
      OUTCORE_RETURN_IF_ERROR(out.add(k % 2 == 0 ? Triangle{p00, p01, p11} : Triangle{p00, p11, p10}));
    }
    lower.swap(upper);
  }
  return Status::Ok();
}

}  // namespace outcore
