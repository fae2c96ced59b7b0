// The text forms of `outcore render`'s camera options: a vector "X,Y,Z"
// (--eye, --center, --up) and an image size "WIDTHxHEIGHT" (--size). Errors
// name the option and echo the value as given.
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>
#include <string>

#include "core/geometry/vec3.h"
#include "core/util/status.h"

namespace outcore {

struct ImageSize {
  uint32_t width = 0;
  uint32_t height = 0;
};

// Three numbers separated by commas, no spaces ("0,-1.5,2e3"). "inf" and
// "nan" parse (the camera then refuses them, naming the option).
Expected<Vec3d> parse_vec3_option(const std::string& option, const std::string& text);
// "640x480" (or "640X480"), each side 1 to kMaxImageSide pixels.
Expected<ImageSize> parse_size_option(const std::string& text);

}  // namespace outcore
