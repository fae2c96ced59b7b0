// The watertight test of Woop, Benthin & Wald 2013 carried out in float64
// throughout (the vertices and the ray converted exactly from float): the
// accuracy reference among the brick structure's tests. Watertight for the
// same reason as the float version (every vertex transformed the same way,
// shared edges give the same edge function up to sign); an edge function that
// is exactly 0 in double counts as on the edge. t, u, v are rounded to float
// for the hit record; tnear is tested on the double t, tfar on the rounded
// one (see hit()).
//
// Thread-safety: pure functions.
#pragma once

#include <cmath>
#include <cstring>
#include <limits>
#include <string_view>
#include <utility>

#include "core/accel/bvh/triangle_hit.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct DoubleTriangleTest {
  static constexpr std::string_view kName = "double";

  struct Prepared {
    double ox, oy, oz;
    double sx, sy, sz;
    int kx, ky, kz;
    Vec3f direction;
  };

  static Prepared prepare(const Ray& ray) {
    const Vec3d d(ray.direction);
    const double ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
    const int kz = (ax >= ay && ax >= az) ? 0 : (ay >= az ? 1 : 2);
    int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
    if (d[kz] < 0.0) std::swap(kx, ky);
    Prepared p;
    p.kx = kx;
    p.ky = ky;
    p.kz = kz;
    p.sx = d[kx] / d[kz];
    p.sy = d[ky] / d[kz];
    p.sz = 1.0 / d[kz];
    p.ox = ray.origin[kx];
    p.oy = ray.origin[ky];
    p.oz = ray.origin[kz];
    p.direction = ray.direction;
    return p;
  }

  // The hit in double precision (t, u, v before rounding); what hit() rounds.
  static bool hit_double(const Prepared& r, const Triangle& tri, double tnear, double tfar, double& t_out,
                         double& u_out, double& v_out) {
    float f[9];
    std::memcpy(f, &tri, sizeof(f));
    double c[9];
    for (int i = 0; i < 9; ++i) c[i] = f[i];
    const double az_ = c[r.kz] - r.oz, bz_ = c[3 + r.kz] - r.oz, cz_ = c[6 + r.kz] - r.oz;
    const double ax = (c[r.kx] - r.ox) - r.sx * az_;
    const double ay = (c[r.ky] - r.oy) - r.sy * az_;
    const double bx = (c[3 + r.kx] - r.ox) - r.sx * bz_;
    const double by = (c[3 + r.ky] - r.oy) - r.sy * bz_;
    const double cx = (c[6 + r.kx] - r.ox) - r.sx * cz_;
    const double cy = (c[6 + r.ky] - r.oy) - r.sy * cz_;
    const double u = cx * by - cy * bx;
    const double v = ax * cy - ay * cx;
    const double w = bx * ay - by * ax;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
    const double det = u + v + w;
    if (det == 0.0) return false;
    if (WatertightTriangleTest::in_plane(r.direction, tri)) return false;  // see there
    const double t = (u * (r.sz * az_) + v * (r.sz * bz_) + w * (r.sz * cz_)) / det;
    if (!(t > tnear && t <= tfar)) return false;
    t_out = t;
    u_out = v / det;
    v_out = w / det;
    return true;
  }

  // The far end is tested on the rounded t: the tie rule compares rounded
  // t's (hit_is_better), and tfar is the best rounded t so far, so two
  // triangles whose double t's round to the same float must both pass it,
  // whichever was found first (else the winner of the tie would depend on
  // traversal and brick order). The near end is decided on the double t.
  static bool hit(const Prepared& r, const Triangle& tri, float tnear, float tfar, TriangleHit& out) {
    double t, u, v;
    if (!hit_double(r, tri, tnear, std::numeric_limits<double>::infinity(), t, u, v)) return false;
    const float rounded = static_cast<float>(t);
    if (!(rounded <= tfar)) return false;
    out = {rounded, static_cast<float>(u), static_cast<float>(v)};
    return true;
  }
};

}  // namespace outcore
