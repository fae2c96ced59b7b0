#include "core/cli/render_options.h"

#include "core/render/pinhole_camera.h"
#include "core/util/parse_number.h"

namespace outcore {

Expected<Vec3d> parse_vec3_option(const std::string& option, const std::string& text) {
  Vec3d v;
  std::size_t start = 0;
  for (int i = 0; i < 3; ++i) {
    const std::size_t comma = text.find(',', start);
    const bool last = i == 2;
    // Exactly two commas: a fourth number is as wrong as a missing one.
    if (last != (comma == std::string::npos) || !parse_number(text.substr(start, comma - start), v[i])) {
      return invalid_argument(option + " '" + text + "': expected three numbers X,Y,Z (e.g. 0,-2.5,10)");
    }
    start = comma + 1;
  }
  return v;
}

Expected<ImageSize> parse_size_option(const std::string& text) {
  const std::size_t x = text.find_first_of("xX");
  // Wider than the result, so that a huge side is "out of range", not "malformed".
  uint64_t width = 0;
  uint64_t height = 0;
  if (x == std::string::npos || !parse_number(text.substr(0, x), width) ||
      !parse_number(text.substr(x + 1), height)) {
    return invalid_argument("--size '" + text + "': expected WIDTHxHEIGHT in pixels (e.g. 640x480)");
  }
  if (width == 0 || height == 0 || width > kMaxImageSide || height > kMaxImageSide) {
    return invalid_argument("--size '" + text + "': width and height must be 1 to " +
                            std::to_string(kMaxImageSide) + " pixels");
  }
  return ImageSize{static_cast<uint32_t>(width), static_cast<uint32_t>(height)};
}

}  // namespace outcore
