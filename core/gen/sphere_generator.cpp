#include "core/gen/sphere_generator.h"

#include <array>
#include <cmath>

namespace outcore {

namespace {

// Unit icosahedron: 12 vertices (0, ±1, ±phi) and cyclic permutations,
// normalised; 20 faces wound counter-clockwise seen from outside.
struct Icosahedron {
  std::array<Vec3d, 12> v;
  static constexpr std::array<std::array<int, 3>, 20> kFaces = {{
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1},
  }};

  Icosahedron() {
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    const std::array<Vec3d, 12> raw = {{{-1, t, 0},
                                        {1, t, 0},
                                        {-1, -t, 0},
                                        {1, -t, 0},
                                        {0, -1, t},
                                        {0, 1, t},
                                        {0, -1, -t},
                                        {0, 1, -t},
                                        {t, 0, -1},
                                        {t, 0, 1},
                                        {-t, 0, -1},
                                        {-t, 0, 1}}};
    for (std::size_t i = 0; i < raw.size(); ++i) v[i] = normalize(raw[i]);
  }
};

const Icosahedron& icosahedron() {
  static const Icosahedron ico;
  return ico;
}

// Symmetric in (a, b): a + b is commutative, the rest depends only on the sum.
Vec3d midpoint_on_sphere(const Vec3d& a, const Vec3d& b) {
  return normalize(a + b);
}

}  // namespace

Expected<SphereConfig> SphereConfig::parse(const GenSpec& spec) {
  SphereConfig c;
  GenParams p(spec);
  p.integer("level", c.level, 0, kMaxLevel);
  p.real("radius", c.radius, RealRange::positive());
  p.real("cx", c.center.x, RealRange::any());
  p.real("cy", c.center.y, RealRange::any());
  p.real("cz", c.center.z, RealRange::any());
  OUTCORE_RETURN_IF_ERROR(p.finish());
  return c;
}

SphereGenerator::SphereGenerator(std::string description, const SphereConfig& config)
    : Generator(std::move(description)), config_(config) {}

Expected<std::unique_ptr<SphereGenerator>> SphereGenerator::create(const GenSpec& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const SphereConfig config, SphereConfig::parse(spec));
  return std::make_unique<SphereGenerator>(spec.text, config);
}

Vec3f SphereGenerator::vertex(const Vec3d& unit) const {
  return to_vertex(config_.center + unit * config_.radius);
}

Status SphereGenerator::subdivide(const Vec3d& a, const Vec3d& b, const Vec3d& c, int depth,
                                  TriangleBatcher& out) const {
  if (depth == 0) return out.add(Triangle{vertex(a), vertex(b), vertex(c)});
  const Vec3d ab = midpoint_on_sphere(a, b);
  const Vec3d bc = midpoint_on_sphere(b, c);
  const Vec3d ca = midpoint_on_sphere(c, a);
  if (depth == 1) {
    // The four leaves below, with each of their six vertices rounded once.
    const Vec3f fa = vertex(a), fb = vertex(b), fc = vertex(c);
    const Vec3f fab = vertex(ab), fbc = vertex(bc), fca = vertex(ca);
    OUTCORE_RETURN_IF_ERROR(out.add(Triangle{fa, fab, fca}));
    OUTCORE_RETURN_IF_ERROR(out.add(Triangle{fab, fb, fbc}));
    OUTCORE_RETURN_IF_ERROR(out.add(Triangle{fca, fbc, fc}));
    return out.add(Triangle{fab, fbc, fca});
  }
  // Corner children first, then the centre one; all keep the parent's winding.
  OUTCORE_RETURN_IF_ERROR(subdivide(a, ab, ca, depth - 1, out));
  OUTCORE_RETURN_IF_ERROR(subdivide(ab, b, bc, depth - 1, out));
  OUTCORE_RETURN_IF_ERROR(subdivide(ca, bc, c, depth - 1, out));
  return subdivide(ab, bc, ca, depth - 1, out);
}

Status SphereGenerator::emit(TriangleBatcher& out) const {
  const Icosahedron& ico = icosahedron();
  for (const auto& f : Icosahedron::kFaces) {
    OUTCORE_RETURN_IF_ERROR(subdivide(ico.v[f[0]], ico.v[f[1]], ico.v[f[2]], config_.level, out));
  }
  return Status::Ok();
}

}  // namespace outcore
