#include "core/gen/stadium_generator.h"

namespace outcore {

namespace {

SphereConfig object_config(const StadiumConfig& c) {
  SphereConfig s;
  s.level = c.level;
  s.radius = c.object;
  s.center = Vec3d(0.0, 1.5 * c.object, 0.0);
  return s;
}

// ni x nj quads of the surface point(i, j), 0 <= i <= ni, 0 <= j <= nj; each
// quad as (p00, p10, p11), (p00, p11, p01), so normals follow dP/di x dP/dj.
template <class Point>
Status emit_grid(int ni, int nj, const Point& point, TriangleBatcher& out) {
  for (int j = 0; j < nj; ++j) {
    for (int i = 0; i < ni; ++i) {
      const Vec3f p00 = to_vertex(point(i, j)), p10 = to_vertex(point(i + 1, j));
      const Vec3f p01 = to_vertex(point(i, j + 1)), p11 = to_vertex(point(i + 1, j + 1));
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{p00, p10, p11}));
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{p00, p11, p01}));
    }
  }
  return Status::Ok();
}

}  // namespace

Expected<StadiumConfig> StadiumConfig::parse(const GenSpec& spec) {
  StadiumConfig c;
  GenParams p(spec);
  p.real("size", c.size, RealRange::positive());
  p.integer("level", c.level, 0, SphereConfig::kMaxLevel);
  p.real("object", c.object, RealRange::positive());
  p.integer("segments", c.segments, 1, kMaxSegments);
  if (!(c.object <= c.size / 4))
    p.fail("object", "must be at most size/4 (the object must fit the enclosure)");
  OUTCORE_RETURN_IF_ERROR(p.finish());
  return c;
}

StadiumGenerator::StadiumGenerator(std::string text, const StadiumConfig& config)
    : Generator(std::move(text)), config_(config), object_(Generator::description(), object_config(config)) {}

Expected<std::unique_ptr<StadiumGenerator>> StadiumGenerator::create(const GenSpec& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const StadiumConfig config, StadiumConfig::parse(spec));
  return std::make_unique<StadiumGenerator>(spec.text, config);
}

uint64_t StadiumGenerator::enclosure_triangle_count() const {
  const auto seg = static_cast<uint64_t>(config_.segments);
  return 2 * seg * seg + 4 * 2 * seg * static_cast<uint64_t>(wall_rows());
}

Status StadiumGenerator::emit(TriangleBatcher& out) const {
  const int seg = config_.segments, rows = wall_rows();
  const double size = config_.size, wall_height = 0.5 * config_.size;
  // Shared by floor and walls, so their common edges use identical coordinates.
  const auto c = [&](int k) {
    return -size + 2.0 * size * static_cast<double>(k) / static_cast<double>(seg);
  };
  const auto h = [&](int k) { return wall_height * static_cast<double>(k) / static_cast<double>(rows); };
  // Floor, normal +y: dP/di = +z, dP/dj = +x.
  OUTCORE_RETURN_IF_ERROR(emit_grid(
      seg, seg, [&](int i, int j) { return Vec3d(c(j), 0.0, c(i)); }, out));
  // Walls, normals pointing inwards.
  OUTCORE_RETURN_IF_ERROR(emit_grid(
      seg, rows, [&](int i, int j) { return Vec3d(size, h(j), c(i)); }, out));
  OUTCORE_RETURN_IF_ERROR(emit_grid(
      seg, rows, [&](int i, int j) { return Vec3d(-size, h(j), c(seg - i)); }, out));
  OUTCORE_RETURN_IF_ERROR(emit_grid(
      seg, rows, [&](int i, int j) { return Vec3d(c(seg - i), h(j), size); }, out));
  OUTCORE_RETURN_IF_ERROR(emit_grid(
      seg, rows, [&](int i, int j) { return Vec3d(c(i), h(j), -size); }, out));
  return object_.emit(out);
}

}  // namespace outcore
