#include "core/render/render_image.h"

#include <algorithm>
#include <cassert>
#include <limits>

namespace outcore {

RenderImage::RenderImage(uint32_t width, uint32_t height, RenderMode mode)
    : width_(width),
      height_(height),
      mode_(mode),
      tmin_(std::numeric_limits<float>::infinity()),
      tmax_(-std::numeric_limits<float>::infinity()) {
  const std::size_t pixels = std::size_t{width} * height;
  if (mode == RenderMode::kDepth) {
    depth_.assign(pixels, std::numeric_limits<float>::infinity());
  } else {
    rgb_.assign(pixels * 3, 0);
  }
}

void RenderImage::add(uint64_t first_pixel, std::span<const Hit> hits) {
  assert(first_pixel + hits.size() <= uint64_t{width_} * height_);
  for (std::size_t i = 0; i < hits.size(); ++i) {
    const Hit& hit = hits[i];
    if (!hit.is_hit()) continue;
    ++hits_;
    const std::size_t pixel = first_pixel + i;
    if (mode_ == RenderMode::kDepth) {
      depth_[pixel] = hit.t;
      tmin_ = std::min(tmin_, hit.t);
      tmax_ = std::max(tmax_, hit.t);
      continue;
    }
    const Rgb c = mode_ == RenderMode::kNormals ? normal_colour(hit.normal) : id_colour(hit.geometry_id);
    rgb_[pixel * 3] = c.r;
    rgb_[pixel * 3 + 1] = c.g;
    rgb_[pixel * 3 + 2] = c.b;
  }
}

std::vector<uint8_t> RenderImage::rgb() const {
  if (mode_ != RenderMode::kDepth) return rgb_;
  std::vector<uint8_t> out(depth_.size() * 3, 0);
  for (std::size_t pixel = 0; pixel < depth_.size(); ++pixel) {
    // A hit's t is finite; a miss keeps the inf it started with.
    if (depth_[pixel] == std::numeric_limits<float>::infinity()) continue;
    const Rgb c = depth_colour(depth_[pixel], tmin_, tmax_);
    out[pixel * 3] = c.r;
    out[pixel * 3 + 1] = c.g;
    out[pixel * 3 + 2] = c.b;
  }
  return out;
}

std::vector<uint8_t> colour_hits(uint32_t width, uint32_t height, RenderMode mode,
                                 std::span<const Hit> hits) {
  RenderImage image(width, height, mode);
  image.add(0, hits);
  return image.rgb();
}

}  // namespace outcore
