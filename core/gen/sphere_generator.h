// SphereGenerator (`gen:sphere`): a closed, watertight icosphere made by
// recursive subdivision of the 20 faces of an icosahedron, depth first, so
// memory is O(level) whatever the triangle count (20 * 4^level).
//
// Watertight by construction: an edge midpoint is normalize(a + b) computed in
// double from the parent endpoints; a + b is commutative, so the two triangles
// sharing an edge compute bit-identical midpoints, and every vertex is rounded
// to float by the same expression. Winding is counter-clockwise seen from
// outside (outward normals).
//
// Parameters: level (0..12, default 3), radius (> 0, default 1),
// cx, cy, cz (centre, default 0).
//
// Thread-safety: see Generator (emit() is const and stateless).
#pragma once

#include <memory>

#include "core/gen/gen_spec.h"
#include "core/gen/generator.h"

namespace outcore {

struct SphereConfig {
  int level = 3;        // subdivision depth: 20 * 4^level triangles
  double radius = 1.0;  // distance of every vertex from the centre
  Vec3d center{0, 0, 0};

  static constexpr int kMaxLevel = 12;  // 335,544,320 triangles
  static Expected<SphereConfig> parse(const GenSpec& spec);
};

class SphereGenerator final : public Generator {
 public:
  SphereGenerator(std::string description, const SphereConfig& config);
  static Expected<std::unique_ptr<SphereGenerator>> create(const GenSpec& spec);

  const SphereConfig& config() const { return config_; }
  uint64_t triangle_count() const override { return 20ull << (2 * config_.level); }
  Status emit(TriangleBatcher& out) const override;

 private:
  Status subdivide(const Vec3d& a, const Vec3d& b, const Vec3d& c, int depth, TriangleBatcher& out) const;
  Vec3f vertex(const Vec3d& unit) const;

  SphereConfig config_;
};

}  // namespace outcore
