#include "core/accel/bsp/bsp_polytope.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/accel/bsp/bsp_directions.h"

namespace outcore {
namespace {

// Twice the vector area of a polygon (its normal times twice its area).
Vec3d twice_vector_area(const Vec3d* v, uint32_t n) {
  Vec3d sum(0, 0, 0);
  for (uint32_t i = 1; i + 1 < n; ++i) sum = sum + cross(v[i] - v[0], v[i + 1] - v[0]);
  return sum;
}

double polygon_area(const Vec3d* v, uint32_t n) {
  return n < 3 ? 0.0 : 0.5 * length(twice_vector_area(v, n));
}

}  // namespace

BspPolytope BspPolytope::box(const Vec3d& lo, const Vec3d& hi) {
  BspPolytope out;
  if (lo.x > hi.x || lo.y > hi.y || lo.z > hi.z) return out;
  const auto corner = [&](int i) {
    return Vec3d(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z);
  };
  // Corner indices of each face, counter-clockwise seen from outside.
  constexpr int kFaces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& face : kFaces) {
    for (const int c : face) out.vertices_.push_back(corner(c));
    out.face_end_.push_back(static_cast<uint32_t>(out.vertices_.size()));
  }
  return out;
}

double BspPolytope::area() const {
  double sum = 0.0;
  uint32_t begin = 0;
  for (const uint32_t end : face_end_) {
    sum += polygon_area(&vertices_[begin], end - begin);
    begin = end;
  }
  return sum;
}

void BspPolytope::extent(uint32_t k, double& lo, double& hi) const {
  lo = hi = 0.0;
  if (vertices_.empty()) return;
  lo = hi = bsp_dot(k, vertices_[0]);
  for (const Vec3d& v : vertices_) {
    const double h = bsp_dot(k, v);
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
}

BspPolytope BspPolytope::clipped(uint32_t k, double s, bool keep_below) const {
  BspPolytope out;
  out.vertices_.reserve(vertices_.size() + 8);
  std::vector<Vec3d> cut;
  const auto inside = [&](double h) { return keep_below ? h <= s : h >= s; };
  uint32_t begin = 0;
  for (const uint32_t end : face_end_) {
    const auto face_start = static_cast<uint32_t>(out.vertices_.size());
    const uint32_t n = end - begin;
    for (uint32_t i = 0; i < n; ++i) {
      const Vec3d& a = vertices_[begin + i];
      const Vec3d& b = vertices_[begin + (i + 1) % n];
      const double ha = bsp_dot(k, a), hb = bsp_dot(k, b);
      if (inside(ha)) out.vertices_.push_back(a);
      if (inside(ha) != inside(hb)) {
        const Vec3d p = a + (b - a) * ((s - ha) / (hb - ha));
        out.vertices_.push_back(p);
        cut.push_back(p);
      }
    }
    if (out.vertices_.size() - face_start >= 3) {
      out.face_end_.push_back(static_cast<uint32_t>(out.vertices_.size()));
    } else {
      out.vertices_.resize(face_start);
    }
    begin = end;
  }
  if (out.face_end_.empty() || cut.size() < 3) return out;
  // The section in the plane, as a new face: its points ordered by angle
  // around their centroid, counter-clockwise seen from outside (the outward
  // normal is +n below, -n above).
  Vec3d center(0, 0, 0);
  for (const Vec3d& p : cut) center = center + p;
  center = center * (1.0 / static_cast<double>(cut.size()));
  const Vec3d normal = bsp_normal(k) * (keep_below ? 1.0 : -1.0);
  const Vec3d any = std::fabs(normal.x) < 0.5 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0);
  const Vec3d u = normalize(cross(normal, any)), v = cross(normalize(normal), u);
  std::sort(cut.begin(), cut.end(), [&](const Vec3d& a, const Vec3d& b) {
    return std::atan2(dot(a - center, v), dot(a - center, u)) <
           std::atan2(dot(b - center, v), dot(b - center, u));
  });
  if (dot(twice_vector_area(cut.data(), static_cast<uint32_t>(cut.size())), normal) < 0.0) {
    std::reverse(cut.begin(), cut.end());
  }
  out.vertices_.insert(out.vertices_.end(), cut.begin(), cut.end());
  out.face_end_.push_back(static_cast<uint32_t>(out.vertices_.size()));
  return out;
}

void BspPolytope::split_areas(uint32_t k, double s, double& below, double& above) const {
  below = above = 0.0;
  // The section's vector area from the faces' cut segments: the faces are
  // consistently oriented, so the segments (where each face's boundary goes
  // from below to above, to where it comes back) chain into the section's
  // boundary, and the sum of their cross products is twice its vector area.
  Vec3d section(0, 0, 0);
  std::array<Vec3d, 64> lower{}, upper{};
  uint32_t begin = 0;
  for (const uint32_t end : face_end_) {
    const uint32_t n = end - begin;
    uint32_t n_lower = 0, n_upper = 0;
    Vec3d rise(0, 0, 0), fall(0, 0, 0);
    for (uint32_t i = 0; i < n && n_lower + 2 < lower.size() && n_upper + 2 < upper.size(); ++i) {
      const Vec3d& a = vertices_[begin + i];
      const Vec3d& b = vertices_[begin + (i + 1) % n];
      const double ha = bsp_dot(k, a), hb = bsp_dot(k, b);
      const bool a_below = ha <= s, b_below = hb <= s;
      (a_below ? lower[n_lower++] : upper[n_upper++]) = a;
      if (a_below != b_below) {
        const Vec3d p = a + (b - a) * ((s - ha) / (hb - ha));
        lower[n_lower++] = p;
        upper[n_upper++] = p;
        (a_below ? rise : fall) = p;
      }
    }
    below += polygon_area(lower.data(), n_lower);
    above += polygon_area(upper.data(), n_upper);
    section = section + cross(rise, fall);
    begin = end;
  }
  const double cap = 0.5 * std::fabs(dot(section, bsp_normal(k))) / bsp_normal_length(k);
  below += cap;
  above += cap;
}

}  // namespace outcore
