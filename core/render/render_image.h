// RenderImage: the picture `outcore render` builds from its rays' hits, one
// band of rows at a time (so a large image never holds all its rays and hits
// at once), coloured by colour_rules.h. Depth needs the nearest and farthest
// hit of the whole image, so in that mode every pixel's t is kept (4 bytes a
// pixel) and the colours are made by rgb(); the other modes colour each hit
// as it arrives.
//
// Pixel (x, y) is ray (x, y) of PinholeRays: row 0 is the first row written,
// as in Open3D's H x W tensor.
//
// Thread-safety: one owner; no internal locking.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/render/colour_rules.h"

namespace outcore {

class RenderImage {
 public:
  RenderImage(uint32_t width, uint32_t height, RenderMode mode);

  // The hits of pixels first_pixel, first_pixel + 1, ... (row by row); they
  // must lie within the image.
  void add(uint64_t first_pixel, std::span<const Hit> hits);

  uint32_t width() const { return width_; }
  uint32_t height() const { return height_; }
  RenderMode mode() const { return mode_; }
  uint64_t hit_count() const { return hits_; }

  // width x height x 3 bytes, row 0 first. Pixels never added are misses.
  std::vector<uint8_t> rgb() const;

 private:
  uint32_t width_;
  uint32_t height_;
  RenderMode mode_;
  uint64_t hits_ = 0;
  std::vector<uint8_t> rgb_;  // normals and ids
  std::vector<float> depth_;  // depth: t per pixel, inf on a miss
  float tmin_;
  float tmax_;
};

// One image from all its hits at once.
std::vector<uint8_t> colour_hits(uint32_t width, uint32_t height, RenderMode mode, std::span<const Hit> hits);

}  // namespace outcore
