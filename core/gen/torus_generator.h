// TorusGenerator (`gen:torus`): a closed, watertight torus around the y axis
// (the ring lies in the xz plane), as an nu x nv grid of quads, each split into
// two triangles: 2 * nu * nv triangles.
//
// Watertight by construction: the vertex of grid point (i, j) is computed from
// (i mod nu, j mod nv) only, so the seams reuse bit-identical vertices. Winding
// is counter-clockwise seen from outside. Memory: two tables of nu and nv
// cos/sin pairs (at most 1 MB).
//
// Parameters: major (ring radius, > 0, default 1), minor (tube radius,
// 0 < minor < major, default 0.25), nu (segments around the ring, 3..32768,
// default 64), nv (segments around the tube, 3..32768, default 32), cx, cy, cz
// (centre, default 0).
//
// Thread-safety: see Generator (emit() is const and stateless).
#pragma once

#include <memory>

#include "core/gen/gen_spec.h"
#include "core/gen/generator.h"

namespace outcore {

struct TorusConfig {
  double major = 1.0;   // distance from the centre to the tube's axis
  double minor = 0.25;  // tube radius, smaller than major
  int nu = 64;          // segments around the ring (y axis)
  int nv = 32;          // segments around the tube
  Vec3d center{0, 0, 0};

  static constexpr int kMaxSegments = 32768;  // 2 * 32768^2 = 2^31 triangles
  static Expected<TorusConfig> parse(const GenSpec& spec);
};

class TorusGenerator final : public Generator {
 public:
  TorusGenerator(std::string description, const TorusConfig& config);
  static Expected<std::unique_ptr<TorusGenerator>> create(const GenSpec& spec);

  const TorusConfig& config() const { return config_; }
  uint64_t triangle_count() const override {
    return 2ull * static_cast<uint64_t>(config_.nu) * static_cast<uint64_t>(config_.nv);
  }
  Status emit(TriangleBatcher& out) const override;

 private:
  TorusConfig config_;
};

}  // namespace outcore
