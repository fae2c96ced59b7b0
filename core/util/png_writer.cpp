#include "core/util/png_writer.h"

#include <zlib.h>

#include <string_view>

#include "core/util/atomic_file.h"

namespace outcore {
namespace {

void put32(std::vector<uint8_t>& out, uint32_t v) {
  out.push_back(static_cast<uint8_t>(v >> 24));
  out.push_back(static_cast<uint8_t>(v >> 16));
  out.push_back(static_cast<uint8_t>(v >> 8));
  out.push_back(static_cast<uint8_t>(v));
}

void chunk(std::vector<uint8_t>& out, const char type[4], std::span<const uint8_t> data) {
  put32(out, static_cast<uint32_t>(data.size()));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data.begin(), data.end());
  put32(out, png_crc32(std::span<const uint8_t>(out.data() + start, out.size() - start)));
}

}  // namespace

uint32_t png_crc32(std::span<const uint8_t> bytes) {
  return static_cast<uint32_t>(::crc32(0L, bytes.data(), static_cast<uInt>(bytes.size())));
}

Expected<std::vector<uint8_t>> encode_png(uint32_t width, uint32_t height, std::span<const uint8_t> rgb) {
  constexpr uint32_t kMaxSide = 1u << 14;
  if (width == 0 || height == 0 || width > kMaxSide || height > kMaxSide)
    return invalid_argument("PNG size " + std::to_string(width) + "x" + std::to_string(height) +
                            " must be between 1 and " + std::to_string(kMaxSide) + " on each side");
  const std::size_t row = std::size_t{width} * 3;
  if (rgb.size() != row * height)
    return invalid_argument("PNG pixel buffer has " + std::to_string(rgb.size()) + " bytes, expected " +
                            std::to_string(row * height));

  // Filtered scanlines: filter type 2 (Up) then each byte minus the one above.
  std::vector<uint8_t> raw((row + 1) * height);
  for (uint32_t y = 0; y < height; ++y) {
    uint8_t* out = raw.data() + y * (row + 1);
    const uint8_t* line = rgb.data() + y * row;
    out[0] = 2;
    for (std::size_t i = 0; i < row; ++i)
      out[1 + i] = static_cast<uint8_t>(line[i] - (y > 0 ? line[i - row] : 0));
  }
  uLongf packed_size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<uint8_t> packed(packed_size);
  if (compress2(packed.data(), &packed_size, raw.data(), static_cast<uLong>(raw.size()), 9) != Z_OK)
    return internal_error("zlib could not compress the PNG image data");
  packed.resize(packed_size);

  std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> header;
  put32(header, width);
  put32(header, height);
  header.insert(header.end(), {8, 2, 0, 0, 0});  // 8-bit RGB, deflate, adaptive filters, no interlace
  chunk(png, "IHDR", header);
  chunk(png, "IDAT", packed);
  chunk(png, "IEND", {});
  return png;
}

Status write_png(const std::string& path, uint32_t width, uint32_t height, std::span<const uint8_t> rgb) {
  OUTCORE_ASSIGN_OR_RETURN(std::vector<uint8_t> png, encode_png(width, height, rgb));
  const std::string_view parts[] = {std::string_view(reinterpret_cast<const char*>(png.data()), png.size())};
  return write_file_atomically(path, parts);
}

}  // namespace outcore
