#include "core/geometry/affine_transform.h"

#include <cmath>
#include <limits>

namespace outcore {
namespace {

template <typename T>
Expected<AffineTransform> transform_from(std::span<const T> rows, const std::string& what) {
  if (rows.size() != 12)
    return invalid_argument(what + ": a transform is 12 numbers (3 rows of 4), got " +
                            std::to_string(rows.size()));
  AffineTransform t;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      const double value = static_cast<double>(rows[r * 4 + c]);
      if (!std::isfinite(value))
        return invalid_argument(what + ": element [" + std::to_string(r) + "][" + std::to_string(c) +
                                "] is not finite");
      t.m[r][c] = value;
    }
  }
  double scale = 1;
  for (int r = 0; r < 3; ++r)
    scale *= std::sqrt(t.m[r][0] * t.m[r][0] + t.m[r][1] * t.m[r][1] + t.m[r][2] * t.m[r][2]);
  if (!(std::fabs(t.determinant()) > 1e-12 * scale))
    return invalid_argument(what + ": the transform is singular (its 3x3 part has determinant " +
                            std::to_string(t.determinant()) + "): it would flatten the mesh");
  return t;
}

float round_down(double x) {
  const float f = static_cast<float>(x);
  return static_cast<double>(f) > x ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
}
float round_up(double x) {
  const float f = static_cast<float>(x);
  return static_cast<double>(f) < x ? std::nextafter(f, std::numeric_limits<float>::infinity()) : f;
}

}  // namespace

Expected<AffineTransform> AffineTransform::from_rows(std::span<const double> rows, const std::string& what) {
  return transform_from(rows, what);
}
Expected<AffineTransform> AffineTransform::from_rows(std::span<const float> rows, const std::string& what) {
  return transform_from(rows, what);
}

Vec3d AffineTransform::point(const Vec3d& p) const {
  return {m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3],
          m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
          m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3]};
}

Vec3d AffineTransform::vector(const Vec3d& v) const {
  return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
          m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
}

double AffineTransform::determinant() const {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

AffineTransform AffineTransform::inverse() const {
  const double inv_det = 1.0 / determinant();
  AffineTransform r;
  r.m[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) * inv_det;
  r.m[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv_det;
  r.m[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv_det;
  r.m[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) * inv_det;
  r.m[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv_det;
  r.m[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv_det;
  r.m[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) * inv_det;
  r.m[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv_det;
  r.m[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv_det;
  const Vec3d offset = r.vector({m[0][3], m[1][3], m[2][3]});
  r.m[0][3] = -offset.x;
  r.m[1][3] = -offset.y;
  r.m[2][3] = -offset.z;
  return r;
}

double AffineTransform::condition_number() const {
  const auto frobenius = [](const AffineTransform& t) {
    double sum = 0;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) sum += t.m[r][c] * t.m[r][c];
    return std::sqrt(sum);
  };
  return frobenius(*this) * frobenius(inverse());
}

bool AffineTransform::is_identity() const {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      if (m[r][c] != (r == c ? 1.0 : 0.0)) return false;
  return true;
}

Aabb AffineTransform::world_box(const Aabb& object) const {
  if (object.empty()) return {};
  Vec3d lo(std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
           std::numeric_limits<double>::infinity());
  Vec3d hi = -lo;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3d p = point({(corner & 1) ? object.hi.x : object.lo.x, (corner & 2) ? object.hi.y : object.lo.y,
                           (corner & 4) ? object.hi.z : object.lo.z});
    lo = min(lo, p);
    hi = max(hi, p);
  }
  // The corners carry double rounding, far below a float's ulp; rounding
  // outward after a pad of that size holds them.
  const double pad = 1e-12 * std::max(max_abs(lo), max_abs(hi));
  Aabb box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = round_down(lo[a] - pad);
    box.hi[a] = round_up(hi[a] + pad);
  }
  return box;
}

Ray AffineTransform::ray_to_object(const Ray& world) const {
  Ray r = world;
  r.origin = Vec3f(point(Vec3d(world.origin)));
  r.direction = Vec3f(vector(Vec3d(world.direction)));
  return r;
}

Vec3f AffineTransform::normal_to_world(const Vec3f& object_normal) const {
  const Vec3d n(object_normal);
  const Vec3d w{m[0][0] * n.x + m[1][0] * n.y + m[2][0] * n.z, m[0][1] * n.x + m[1][1] * n.y + m[2][1] * n.z,
                m[0][2] * n.x + m[1][2] * n.y + m[2][2] * n.z};
  return Vec3f(normalize(w));
}

}  // namespace outcore
