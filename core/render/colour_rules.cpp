#include "core/render/colour_rules.h"

#include <cmath>

namespace outcore {

namespace {

// Round half away from zero, then clamp: the same byte for every value the
// Python side computes with the same float64 steps. NaN is black.
uint8_t channel(double value) {
  if (!(value > 0)) return 0;
  if (value >= 255) return 255;
  return static_cast<uint8_t>(std::lround(value));
}

}  // namespace

Expected<RenderMode> render_mode_from_name(const std::string& name) {
  if (name == "depth") return RenderMode::kDepth;
  if (name == "normals") return RenderMode::kNormals;
  if (name == "ids") return RenderMode::kIds;
  return invalid_argument("--mode '" + name + "': must be depth, normals or ids");
}

const char* render_mode_name(RenderMode mode) {
  switch (mode) {
    case RenderMode::kDepth: return "depth";
    case RenderMode::kNormals: return "normals";
    case RenderMode::kIds: return "ids";
  }
  return "?";
}

Rgb depth_ramp(double s) {
  if (!(s > 0)) return kDepthStops.front();
  if (s >= 1) return kDepthStops.back();
  // numpy.interp's arithmetic: slope * (s - x_j) + y_j. The stops are 0.25
  // apart, so s * 4 and s - x_j are exact and any linear formula built from
  // them rounds the same.
  const int j = static_cast<int>(s * 4);
  const double x0 = 0.25 * j;
  const Rgb& a = kDepthStops[j];
  const Rgb& b = kDepthStops[j + 1];
  const auto lerp = [&](uint8_t from, uint8_t to) {
    const double slope = (static_cast<double>(to) - static_cast<double>(from)) / 0.25;
    return channel(slope * (s - x0) + static_cast<double>(from));
  };
  return {lerp(a.r, b.r), lerp(a.g, b.g), lerp(a.b, b.b)};
}

Rgb depth_colour(float t, double tmin, double tmax) {
  const double v = tmax == tmin ? 0.0 : (double{t} - tmin) / (tmax - tmin);
  return depth_ramp(1.0 - v);
}

Rgb normal_colour(const Vec3f& normal) {
  const auto c = [](float n) { return channel(255.0 * (double{n} * 0.5 + 0.5)); };
  return {c(normal.x), c(normal.y), c(normal.z)};
}

uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  uint64_t z = x;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

Rgb id_colour(uint32_t geometry_id) {
  const uint64_t z = splitmix64(geometry_id);
  const auto c = [z](int byte) { return static_cast<uint8_t>(64 + ((z >> (8 * byte)) & 0xff) % 192); };
  return {c(0), c(1), c(2)};
}

}  // namespace outcore
