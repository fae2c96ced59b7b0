#include "core/upper/oriented_box.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/upper/bound_segment.h"

namespace outcore {
namespace {

constexpr double kInfD = std::numeric_limits<double>::infinity();
// Triangles whose frames fit() tries (the largest by area).
constexpr std::size_t kFrameCandidates = 8;

// Eigenvectors of the symmetric 3x3 matrix `m` (Jacobi rotations), as rows.
std::array<Vec3d, 3> principal_axes(std::array<std::array<double, 3>, 3> m) {
  std::array<std::array<double, 3>, 3> v{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  for (int sweep = 0; sweep < 32; ++sweep) {
    const double off = std::fabs(m[0][1]) + std::fabs(m[0][2]) + std::fabs(m[1][2]);
    if (off < 1e-300) break;
    for (int p = 0; p < 2; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        if (m[p][q] == 0) continue;
        const double theta = (m[q][q] - m[p][p]) / (2 * m[p][q]);
        const double t = (theta >= 0 ? 1 : -1) / (std::fabs(theta) + std::sqrt(theta * theta + 1));
        const double c = 1 / std::sqrt(t * t + 1), s = t * c;
        for (int k = 0; k < 3; ++k) {  // m = J^T m J
          const double mkp = m[k][p], mkq = m[k][q];
          m[k][p] = c * mkp - s * mkq;
          m[k][q] = s * mkp + c * mkq;
        }
        for (int k = 0; k < 3; ++k) {
          const double mpk = m[p][k], mqk = m[q][k];
          m[p][k] = c * mpk - s * mqk;
          m[q][k] = s * mpk + c * mqk;
        }
        for (int k = 0; k < 3; ++k) {
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
  return {Vec3d(v[0][0], v[1][0], v[2][0]), Vec3d(v[0][1], v[1][1], v[2][1]),
          Vec3d(v[0][2], v[1][2], v[2][2])};
}

// A right-handed orthonormal frame from a first axis and a direction not
// parallel to it; nullopt-like (false) when they are.
bool frame_from(const Vec3d& first, const Vec3d& toward, std::array<Vec3f, 3>& out) {
  const double n = length(first);
  if (!(n > 0)) return false;
  const Vec3d a = first / n;
  const Vec3d b_raw = toward - a * dot(a, toward);
  const double bn = length(b_raw);
  if (!(bn > 1e-12 * length(toward))) return false;
  const Vec3d b = b_raw / bn;
  const Vec3d c = cross(a, b);
  for (int k = 0; k < 3; ++k) {
    const Vec3d& axis = k == 0 ? a : (k == 1 ? b : c);
    out[k] = Vec3f(static_cast<float>(axis.x), static_cast<float>(axis.y), static_cast<float>(axis.z));
  }
  return true;
}

std::array<Vec3f, 3> pca_frame(std::span<const Triangle> triangles) {
  Vec3d mean(0, 0, 0);
  for (const Triangle& tri : triangles) mean = mean + Vec3d(tri.v0) + Vec3d(tri.v1) + Vec3d(tri.v2);
  mean = mean / (3.0 * static_cast<double>(triangles.size()));
  std::array<std::array<double, 3>, 3> cov{};
  for (const Triangle& tri : triangles) {
    for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
      const Vec3d p = Vec3d(v) - mean;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) cov[i][j] += p[i] * p[j];
    }
  }
  const std::array<Vec3d, 3> axes = principal_axes(cov);
  std::array<Vec3f, 3> frame{Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)};
  frame_from(axes[0], axes[1], frame);  // orthonormalised; the world frame if degenerate
  return frame;
}

}  // namespace

OrientedBox OrientedBox::in_frame(std::span<const Triangle> triangles, const std::array<Vec3f, 3>& axes) {
  OrientedBox box;
  box.axes = axes;
  if (triangles.empty()) return box;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int k = 0; k < 3; ++k) {
    const Vec3d axis(axes[k]);
    double lo = kInfD, hi = -kInfD, magnitude = 0;
    for (const Triangle& tri : triangles) {
      for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
        const Vec3d p(v);
        const double projection = dot(axis, p);
        lo = std::min(lo, projection);
        hi = std::max(hi, projection);
        magnitude =
            std::max(magnitude, std::fabs(axis.x * p.x) + std::fabs(axis.y * p.y) + std::fabs(axis.z * p.z));
      }
    }
    // float64 projection error is ~1e-16 of `magnitude`; the pad covers it
    // many times over before the outward rounding to float.
    const double pad = 0x1p-40 * magnitude;
    box.lo[k] = std::nextafter(static_cast<float>(lo - pad), -kInf);
    box.hi[k] = std::nextafter(static_cast<float>(hi + pad), kInf);
  }
  return box;
}

OrientedBox OrientedBox::fit(std::span<const Triangle> triangles) {
  if (triangles.empty()) return OrientedBox{};
  std::vector<std::array<Vec3f, 3>> frames;
  frames.push_back({Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)});
  frames.push_back(pca_frame(triangles));
  // The largest triangles' own frames.
  std::vector<std::pair<double, std::size_t>> by_area;
  by_area.reserve(triangles.size());
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    const Triangle& tri = triangles[k];
    by_area.emplace_back(length(cross(Vec3d(tri.v1) - Vec3d(tri.v0), Vec3d(tri.v2) - Vec3d(tri.v0))), k);
  }
  const std::size_t take = std::min(kFrameCandidates, by_area.size());
  std::partial_sort(by_area.begin(), by_area.begin() + static_cast<std::ptrdiff_t>(take), by_area.end(),
                    [](const auto& a, const auto& b) { return a.first > b.first; });
  for (std::size_t k = 0; k < take; ++k) {
    const Triangle& tri = triangles[by_area[k].second];
    const Vec3d e0 = Vec3d(tri.v1) - Vec3d(tri.v0), e1 = Vec3d(tri.v2) - Vec3d(tri.v1),
                e2 = Vec3d(tri.v0) - Vec3d(tri.v2);
    const Vec3d longest = dot(e0, e0) >= dot(e1, e1) && dot(e0, e0) >= dot(e2, e2)
                              ? e0
                              : (dot(e1, e1) >= dot(e2, e2) ? e1 : e2);
    std::array<Vec3f, 3> frame;
    if (frame_from(cross(e0, -e2), longest, frame)) frames.push_back(frame);
  }
  OrientedBox best;
  double best_area = kInfD;
  for (const auto& frame : frames) {
    const OrientedBox box = in_frame(triangles, frame);
    const double area = box.surface_area();
    if (area < best_area) {
      best_area = area;
      best = box;
    }
  }
  return best;
}

double OrientedBox::volume() const {
  if (empty()) return 0;
  return (static_cast<double>(hi[0]) - lo[0]) * (static_cast<double>(hi[1]) - lo[1]) *
         (static_cast<double>(hi[2]) - lo[2]);
}

double OrientedBox::surface_area() const {
  if (empty()) return 0;
  const double a = static_cast<double>(hi[0]) - lo[0], b = static_cast<double>(hi[1]) - lo[1],
               c = static_cast<double>(hi[2]) - lo[2];
  return 2 * (a * b + b * c + c * a);
}

bool OrientedBox::may_hit(const Ray& ray, float tmin, float tmax, double rounding_scale) const {
  if (empty()) return false;
  const Vec3d o(ray.origin), d(ray.direction);
  double magnitude = 0;
  for (int k = 0; k < 3; ++k)
    magnitude =
        std::max({magnitude, std::fabs(static_cast<double>(lo[k])), std::fabs(static_cast<double>(hi[k]))});
  // E of hit_rounding.h (in the max norm), and how far moving a point by E
  // in each coordinate can move its projection on an axis (|axis|_1 <= sqrt 3).
  const double rounding = rounding_scale * (max_abs(o) + magnitude) * 1.7320508075688772;
  double enter = -kInfD, leave = kInfD;
  for (int k = 0; k < 3; ++k) {
    const Vec3d axis(axes[k]);
    const double ok = dot(axis, o), dk = dot(axis, d);
    const double slab_lo = lo[k] - rounding, slab_hi = hi[k] + rounding;
    if (dk == 0) {
      if (ok < slab_lo || ok > slab_hi) return false;
      continue;
    }
    double t0 = (slab_lo - ok) / dk, t1 = (slab_hi - ok) / dk;
    if (t0 > t1) std::swap(t0, t1);
    enter = std::max(enter, t0);
    leave = std::min(leave, t1);
  }
  return bound_segment_overlaps(enter, leave, tmin, tmax);
}

}  // namespace outcore
