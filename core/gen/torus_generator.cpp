#include "core/gen/torus_generator.h"

#include <cmath>
#include <numbers>
#include <vector>

namespace outcore {

namespace {

struct CosSin {
  double c, s;
};

// cos/sin of 2*pi*k/n for k in [0, n); index k mod n gives the wrap-around.
std::vector<CosSin> angle_table(int n) {
  std::vector<CosSin> t(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double a = 2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(n);
    t[static_cast<std::size_t>(k)] = {std::cos(a), std::sin(a)};
  }
  return t;
}

}  // namespace

Expected<TorusConfig> TorusConfig::parse(const GenSpec& spec) {
  TorusConfig c;
  GenParams p(spec);
  p.real("major", c.major, RealRange::positive());
  p.real("minor", c.minor, RealRange::positive());
  p.integer("nu", c.nu, 3, kMaxSegments);
  p.integer("nv", c.nv, 3, kMaxSegments);
  p.real("cx", c.center.x, RealRange::any());
  p.real("cy", c.center.y, RealRange::any());
  p.real("cz", c.center.z, RealRange::any());
  if (!(c.minor < c.major)) {
    p.fail("minor", "must be smaller than major (a torus with minor >= major intersects itself)");
  }
  OUTCORE_RETURN_IF_ERROR(p.finish());
  return c;
}

TorusGenerator::TorusGenerator(std::string description, const TorusConfig& config)
    : Generator(std::move(description)), config_(config) {}

Expected<std::unique_ptr<TorusGenerator>> TorusGenerator::create(const GenSpec& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const TorusConfig config, TorusConfig::parse(spec));
  return std::make_unique<TorusGenerator>(spec.text, config);
}

Status TorusGenerator::emit(TriangleBatcher& out) const {
  const TorusConfig& c = config_;
  const std::vector<CosSin> ring = angle_table(c.nu);
  const std::vector<CosSin> tube = angle_table(c.nv);
  const auto vertex = [&](int i, int j) {
    const CosSin u = ring[static_cast<std::size_t>(i % c.nu)];
    const CosSin v = tube[static_cast<std::size_t>(j % c.nv)];
    const double r = c.major + c.minor * v.c;
    return to_vertex(c.center + Vec3d(r * u.c, c.minor * v.s, r * u.s));
  };
  // P(u, v) = ((R + r cos v) cos u, r sin v, (R + r cos v) sin u): dP/dv x dP/du
  // points outward, so the quad (i,j) (i,j+1) (i+1,j+1) (i+1,j) is counter-clockwise
  // seen from outside.
  for (int i = 0; i < c.nu; ++i) {
    for (int j = 0; j < c.nv; ++j) {
      const Vec3f p00 = vertex(i, j), p01 = vertex(i, j + 1);
      const Vec3f p10 = vertex(i + 1, j), p11 = vertex(i + 1, j + 1);
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{p00, p01, p11}));
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{p00, p11, p10}));
    }
  }
  return Status::Ok();
}

}  // namespace outcore
