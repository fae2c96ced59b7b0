// The camera rays of `outcore render`: exactly (bitwise) the rays of Open3D
// 0.20's RaycastingScene.create_rays_pinhole(fov_deg, center, eye, up,
// width_px, height_px), so that a picture rendered here, by the Python
// client's outcore.render, or by Open3D itself shows the same pixels.
//
// Open3D's conventions, kept as they are (checked against Open3D 0.20):
// - fov_deg is the horizontal field of view; the focal length is
//   0.5 * width / tan(fov / 2) pixels for both axes, the principal point the
//   image centre (width / 2, height / 2);
// - ray (row y, column x) goes through the pixel centre (x + 0.5, y + 0.5);
// - every ray starts at the eye; directions are not unit length: each has
//   length 1 along the view direction, so t_hit is the depth along the
//   optical axis, not the distance to the eye;
// - the camera's y axis is `up` (made orthogonal to the view direction) and
//   rows go along it: row 0 looks towards -up and column 0 towards
//   up x view. Written top row first, a picture whose `up` is the world's up
//   is therefore upside down and mirrored (turned by 180 degrees); `outcore
//   render` asks for the world's down so that its pictures are upright.
// Rays are made in rows, row 0 first (the H x W layout of Open3D's tensor).
//
// Thread-safety: PinholeRays is immutable after make(); rows() may be called
// from several threads at once.
#pragma once

#include <cstdint>
#include <span>

#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"
#include "core/util/status.h"

namespace outcore {

// PNG's limit, and ours: 16,384 pixels on a side.
inline constexpr uint32_t kMaxImageSide = 1u << 14;

struct PinholeCamera {
  Vec3d eye;
  Vec3d center;  // a point the camera looks at
  Vec3d up;
  double fov_deg = 0;  // horizontal, in (0, 180)
  uint32_t width = 0;  // pixels
  uint32_t height = 0;
};

// The rays of one camera, made row by row.
class PinholeRays {
 public:
  // INVALID_ARGUMENT naming the `outcore render` option and its value
  // (--eye, --center, --up, --fov, --size) when the camera has no rays: a
  // size outside 1..kMaxImageSide, a field of view outside (0, 180),
  // non-finite vectors, an eye beyond the largest coordinate the engine
  // traces, eye == center, a zero up or one parallel to the view direction.
  static Expected<PinholeRays> make(const PinholeCamera& camera);

  uint32_t width() const { return width_; }
  uint32_t height() const { return height_; }
  uint64_t pixel_count() const { return uint64_t{width_} * height_; }

  // Ray of pixel (x, y).
  Ray ray(uint32_t x, uint32_t y) const;
  // Rows first_row .. first_row + out.size() / width() - 1, row by row;
  // out.size() must be a multiple of width() and the rows within the image.
  void rows(uint32_t first_row, std::span<Ray> out) const;

 private:
  PinholeRays() = default;

  Vec3f origin_;
  // Camera to world times the inverse intrinsics, rounded to float as Open3D
  // does: direction = m_ * (x + 0.5, y + 0.5, 1).
  float m_[3][3] = {};
  uint32_t width_ = 0;
  uint32_t height_ = 0;
};

}  // namespace outcore
