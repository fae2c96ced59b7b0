// triangle_may_touch_box and TriangleBoxOverlap: never false for a box a
// point of the triangle lies in (sampled densely, and boxes whose face or
// corner passes exactly through a vertex), at the origin and at offsets up
// to 1e6, with the margin the structures grow their cells by; false for boxes inside the bounds but off the
// triangle; the per-triangle form agrees with the one-shot test on boxes overlapping the bounds, and
// TrianglePlaneOverlap with its plane test.
#include "core/geometry/triangle_box_overlap.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

Vec3d lerp3(const Triangle& t, double u, double v) {
  return Vec3d(t.v0) * (1.0 - u - v) + Vec3d(t.v1) * u + Vec3d(t.v2) * v;
}

Triangle random_triangle(std::mt19937_64& rng, double offset) {
  std::uniform_real_distribution<float> coordinate(-1.0f, 1.0f);
  auto point = [&] {
    return Vec3f(static_cast<float>(offset + coordinate(rng)), static_cast<float>(offset + coordinate(rng)),
                 static_cast<float>(offset + coordinate(rng)));
  };
  return Triangle{point(), point(), point()};
}

bool bounds_overlap(const Triangle& t, const Vec3d& lo, const Vec3d& hi) {
  const Aabb b = t.bounds();
  for (int a = 0; a < 3; ++a) {
    if (b.lo[a] > hi[a] || b.hi[a] < lo[a]) return false;
  }
  return true;
}

TEST(TriangleBoxOverlap, NeverRejectsABoxHoldingAPointOfTheTriangle) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (const double offset : {0.0, 1e3, 1e6}) {
    std::size_t checked = 0;
    for (int t = 0; t < 300; ++t) {
      const Triangle tri = random_triangle(rng, offset);
      const TriangleBoxOverlap overlap(tri);
      for (int s = 0; s < 40; ++s) {
        double u = unit(rng), v = unit(rng);
        if (u + v > 1) u = 1 - u, v = 1 - v;
        const Vec3d p = s < 3 ? Vec3d(s == 0 ? tri.v0 : s == 1 ? tri.v1 : tri.v2) : lerp3(tri, u, v);
        // Boxes of several sizes with p inside, on a face, or at a corner.
        const double size = 0.001 * (1 + s % 7) * (s % 2 == 0 ? 1 : 100);
        const Vec3d shift(unit(rng), unit(rng), unit(rng));
        Vec3d lo = p - shift * size, hi = lo + Vec3d(size, size, size);
        if (s % 5 == 1) lo = p, hi = p + Vec3d(size, size, size);  // p at the low corner
        if (s % 5 == 2) hi = p, lo = p - Vec3d(size, size, size);  // at the high corner
        if (s % 5 == 3) lo.x = hi.x = p.x;                         // a flat box through p
        // The margin the structures grow their cells by (p itself is
        // rounded in float64, by up to 1e-10 at 1e6).
        const Aabb region{
            Vec3f(static_cast<float>(lo.x), static_cast<float>(lo.y), static_cast<float>(lo.z)),
            Vec3f(static_cast<float>(hi.x), static_cast<float>(hi.y), static_cast<float>(hi.z))};
        const double margin = cell_filing_margin(region, hi - lo);
        EXPECT_TRUE(triangle_may_touch_box(tri, lo, hi, margin)) << "offset " << offset;
        if (bounds_overlap(tri, lo, hi)) {
          EXPECT_TRUE(overlap.may_touch_overlapping_box(lo, hi, margin)) << "offset " << offset;
          EXPECT_TRUE(overlap.plane_may_touch_box(lo, hi, margin)) << "offset " << offset;
          for (int axis = 0; axis < 3; ++axis) {
            EXPECT_TRUE(overlap.may_touch_overlapping_column(lo, hi, margin, axis)) << "offset " << offset;
          }
          ++checked;
        }
      }
    }
    EXPECT_GT(checked, 5000u);
  }
}

TEST(TriangleBoxOverlap, RejectsBoxesWithinTheBoundsButOffTheTriangle) {
  // The triangle x + y + z = 1 in the first octant: the boxes at the
  // bounds' far corner (1, 1, 1) and at the origin lie within its bounds
  // and miss it.
  const Triangle tri{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const TriangleBoxOverlap overlap(tri);
  for (const auto& [lo, hi] :
       std::vector<std::pair<Vec3d, Vec3d>>{{{0.8, 0.8, 0.8}, {1, 1, 1}}, {{0, 0, 0}, {0.2, 0.2, 0.2}}}) {
    EXPECT_FALSE(triangle_may_touch_box(tri, lo, hi, 0.0));
    EXPECT_FALSE(overlap.may_touch_overlapping_box(lo, hi, 0.0));
  }
  // One that the edge-by-axis products separate: near the corner (1, 1, 0),
  // beyond the edge from (1, 0, 0) to (0, 1, 0), but within the plane's
  // reach.
  const Vec3d lo{0.7, 0.7, 0.0}, hi{0.9, 0.9, 0.05};
  EXPECT_FALSE(triangle_may_touch_box(tri, lo, hi, 0.0));
  EXPECT_FALSE(overlap.may_touch_overlapping_box(lo, hi, 0.0));
  // The column over (0.8, 0.8) along z misses it (x + y > 1 there); the
  // one over (0.2, 0.2) meets it.
  EXPECT_FALSE(overlap.may_touch_overlapping_column({0.8, 0.8, 0}, {0.9, 0.9, 1}, 0.0, 2));
  EXPECT_TRUE(overlap.may_touch_overlapping_column({0.2, 0.2, 0.9}, {0.3, 0.3, 1}, 0.0, 2));
  // And one it touches.
  EXPECT_TRUE(overlap.may_touch_overlapping_box({0.3, 0.3, 0.3}, {0.4, 0.4, 0.4}, 0.0));
}

TEST(TriangleBoxOverlap, ThePerTriangleFormAgreesWithTheOneShotTest) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::size_t boxes = 0, disagreements = 0, rejected = 0;
  std::size_t plane_stricter = 0, plane_looser = 0, plane_rejected = 0;
  std::size_t column_stricter = 0, column_rejected = 0;
  for (int t = 0; t < 500; ++t) {
    const Triangle tri = random_triangle(rng, 0.0);
    const TriangleBoxOverlap overlap(tri);
    const TrianglePlaneOverlap plane_only(tri);
    const Aabb b = tri.bounds();
    for (int s = 0; s < 50; ++s) {
      Vec3d lo, hi;
      for (int a = 0; a < 3; ++a) {
        const double extent = b.hi[a] - b.lo[a];
        lo[a] = b.lo[a] + unit(rng) * extent;
        hi[a] = lo[a] + unit(rng) * 0.3 * extent;
      }
      ++boxes;
      const bool one_shot = triangle_may_touch_box(tri, lo, hi, 1e-9);
      rejected += !one_shot;
      disagreements += one_shot != overlap.may_touch_overlapping_box(lo, hi, 1e-9);
      // The plane test is looser, never stricter.
      const bool plane = overlap.plane_may_touch_box(lo, hi, 1e-9);
      disagreements += plane != plane_only.plane_may_touch_box(lo, hi, 1e-9);
      plane_stricter += one_shot && !plane;
      plane_looser += plane && !one_shot;
      plane_rejected += !plane;
      // A column holds the box, so it is rejected only where the box is.
      for (int axis = 0; axis < 3; ++axis) {
        const bool column = overlap.may_touch_overlapping_column(lo, hi, 1e-9, axis);
        column_stricter += one_shot && !column;
        column_rejected += !column;
      }
    }
  }
  EXPECT_GT(rejected, boxes / 10);  // the boxes are not all trivially touched
  EXPECT_EQ(disagreements, 0u);
  EXPECT_EQ(plane_stricter, 0u);
  EXPECT_GT(plane_looser, 0u);
  EXPECT_GT(plane_rejected, boxes / 20);  // the plane alone still rejects boxes
  EXPECT_EQ(column_stricter, 0u);
  EXPECT_GT(column_rejected, boxes / 20);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
