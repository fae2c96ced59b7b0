// RenderImage and render_bands: misses are black in every mode, depth spans
// the whole image's hits (not a band's), the picture does not depend on how
// the rays were cut into bands, and a tracer's error ends the render.
#include "core/render/render_image.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/render/band_renderer.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

Hit hit_at(float t, uint32_t geometry, Vec3f normal) {
  Hit h;
  h.t = t;
  h.geometry_id = geometry;
  h.primitive_id = 0;
  h.normal = normal;
  return h;
}

Rgb pixel(const std::vector<uint8_t>& rgb, std::size_t i) {
  return {rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]};
}

TEST(RenderImageTest, ColoursEachModeAndLeavesMissesBlack) {
  const std::vector<Hit> hits = {hit_at(4, 1, {0, 0, 1}), Hit{}, hit_at(2, 0, {1, 0, 0}),
                                 hit_at(8, 3, {0, -1, 0})};
  const auto depth = colour_hits(2, 2, RenderMode::kDepth, hits);
  ASSERT_EQ(depth.size(), 12u);
  EXPECT_EQ(pixel(depth, 0), depth_colour(4, 2, 8));
  EXPECT_EQ(pixel(depth, 1), kMissColour);
  EXPECT_EQ(pixel(depth, 2), kDepthStops.back());   // nearest
  EXPECT_EQ(pixel(depth, 3), kDepthStops.front());  // farthest
  const auto normals = colour_hits(2, 2, RenderMode::kNormals, hits);
  EXPECT_EQ(pixel(normals, 0), normal_colour({0, 0, 1}));
  EXPECT_EQ(pixel(normals, 1), kMissColour);
  EXPECT_EQ(pixel(normals, 3), normal_colour({0, -1, 0}));
  const auto ids = colour_hits(2, 2, RenderMode::kIds, hits);
  EXPECT_EQ(pixel(ids, 0), id_colour(1));
  EXPECT_EQ(pixel(ids, 1), kMissColour);
  EXPECT_EQ(pixel(ids, 2), id_colour(0));
  RenderImage image(2, 2, RenderMode::kIds);
  image.add(0, hits);
  EXPECT_EQ(image.hit_count(), 3u);
}

TEST(RenderImageTest, AnImageWithoutHitsIsBlack) {
  const std::vector<Hit> misses(6);
  for (RenderMode mode : {RenderMode::kDepth, RenderMode::kNormals, RenderMode::kIds})
    EXPECT_EQ(colour_hits(3, 2, mode, misses), std::vector<uint8_t>(18, 0));
}

// A stand-in for the engine: every ray whose direction's x is positive hits
// at t = 1 + |dx| * 10, geometry 0 or 1 by the sign of dy.
Status fake_trace(std::span<const Ray> rays, std::span<Hit> hits) {
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Vec3f d = rays[i].direction;
    hits[i] = d.x > 0 ? hit_at(1 + std::abs(d.x) * 10, d.y > 0 ? 1 : 0, normalize(d)) : Hit{};
  }
  return Status::Ok();
}

TEST(RenderBandsTest, BandsDoNotChangeThePicture) {
  PinholeCamera c;
  c.eye = {0, 0, 0};
  c.center = {0, 0, -1};
  c.up = {0, -1, 0};
  c.fov_deg = 70;
  c.width = 13;
  c.height = 9;
  auto camera = PinholeRays::make(c);
  ASSERT_TRUE(camera.ok());
  std::vector<Ray> rays(camera->pixel_count());
  camera->rows(0, rays);
  std::vector<Hit> hits(rays.size());
  ASSERT_TRUE(fake_trace(rays, hits).ok());
  for (RenderMode mode : {RenderMode::kDepth, RenderMode::kNormals, RenderMode::kIds}) {
    const auto whole = colour_hits(c.width, c.height, mode, hits);
    for (uint64_t band : {uint64_t{1}, uint64_t{13}, uint64_t{40}, uint64_t{1} << 20}) {
      RenderReport report;
      uint64_t last_progress = 0;
      auto rgb = render_bands(*camera, mode, fake_trace, &report, band, [&](uint64_t done, uint64_t total) {
        EXPECT_GT(done, last_progress);
        EXPECT_EQ(total, 117u);
        last_progress = done;
      });
      ASSERT_TRUE(rgb.ok());
      EXPECT_EQ(*rgb, whole) << "band " << band;
      EXPECT_EQ(report.rays, 117u);
      EXPECT_EQ(last_progress, 117u);
      // Whole rows per band, at least one.
      EXPECT_EQ(report.bands, band <= 13 ? 9u : band == 40 ? 3u : 1u);
      EXPECT_GT(report.hits, 0u);
      EXPECT_LT(report.hits, 117u);
    }
  }
}

TEST(RenderBandsTest, ATracersErrorEndsTheRender) {
  PinholeCamera c;
  c.eye = {0, 0, 0};
  c.center = {1, 0, 0};
  c.up = {0, 0, 1};
  c.fov_deg = 40;
  c.width = 4;
  c.height = 4;
  auto camera = PinholeRays::make(c);
  ASSERT_TRUE(camera.ok());
  int calls = 0;
  auto rgb = render_bands(
      *camera, RenderMode::kDepth,
      [&](std::span<const Ray>, std::span<Hit>) {
        return ++calls == 2 ? io_error("the server went away") : Status::Ok();
      },
      nullptr, 4);
  ASSERT_FALSE(rgb.ok());
  EXPECT_EQ(rgb.status().message(), "the server went away");
  EXPECT_EQ(calls, 2);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
