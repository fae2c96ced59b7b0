// Tests of the brick features the cost model reads (brick_features.h), on
// shapes whose values are known: a plane, a cube's surface, everything in
// one corner, nothing.
#include "core/accel/auto/brick_features.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

std::vector<Triangle> cube_surface(float size) {
  const auto p = [&](int x, int y, int z) { return Vec3f(x * size, y * size, z * size); };
  std::vector<Triangle> out;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      Vec3f c[4];
      for (int k = 0; k < 4; ++k) {
        int v[3];
        v[axis] = side;
        v[(axis + 1) % 3] = k & 1;
        v[(axis + 2) % 3] = (k >> 1) & 1;
        c[k] = p(v[0], v[1], v[2]);
      }
      out.push_back({c[0], c[1], c[3]});
      out.push_back({c[0], c[3], c[2]});
    }
  }
  return out;
}

TEST(BrickFeatures, ACubesSurfaceFillsItsBoxAndIsNotFlat) {
  const BrickFeatures f = measure_brick_features(cube_surface(3.0f));
  EXPECT_EQ(f.triangles, 12u);
  EXPECT_DOUBLE_EQ(f.flatness, 1.0);
  EXPECT_NEAR(f.area_ratio, 1.0, 1e-12);
  const auto x = f.regressors();
  EXPECT_EQ(x[0], 1.0);
  EXPECT_DOUBLE_EQ(x[1], std::log2(13.0));
  EXPECT_DOUBLE_EQ(x[4], 1.0);
}

TEST(BrickFeatures, APlaneIsFlatAndEvenlySpread) {
  std::vector<Triangle> plane;
  for (int i = 0; i < 16; ++i) {
    for (int j = 0; j < 16; ++j) {
      const Vec3f a(i, j, 0), b(i + 1, j, 0), c(i, j + 1, 0);
      plane.push_back({a, b, c});
    }
  }
  const BrickFeatures f = measure_brick_features(plane);
  EXPECT_EQ(f.flatness, 0.0);
  // 16 of the 64 cells (one layer) hold all: the fullest is 4x the mean.
  EXPECT_NEAR(f.density_spread, 2.0, 0.2);
  // Half the plane's area is covered, and its box's surface is twice the plane.
  EXPECT_NEAR(f.area_ratio, 0.25, 1e-9);
}

TEST(BrickFeatures, ATeapotInAStadiumIsSpread) {
  std::vector<Triangle> scene = cube_surface(1000.0f);  // the stadium
  for (int k = 0; k < 500; ++k) {                       // the teapot, in one corner
    const float s = 1.0f + k * 0.001f;
    scene.push_back({Vec3f(s, s, s), Vec3f(s + 1, s, s), Vec3f(s, s + 1, s)});
  }
  const BrickFeatures f = measure_brick_features(scene);
  EXPECT_GT(f.density_spread, 5.5);
  EXPECT_LE(f.density_spread, 6.0);
}

TEST(BrickFeatures, NothingGivesZeros) {
  const BrickFeatures f = measure_brick_features({});
  EXPECT_EQ(f.triangles, 0u);
  EXPECT_EQ(f.density_spread, 0.0);
  EXPECT_EQ(f.area_ratio, 0.0);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
