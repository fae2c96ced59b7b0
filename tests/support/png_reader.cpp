#include "tests/support/png_reader.h"

#include <zlib.h>

#include <cstdlib>
#include <cstring>

#include "tests/support/test_paths.h"

namespace outcore::testing {

namespace {

uint32_t get32(const std::string& b, std::size_t at) {
  const auto byte = [&](std::size_t i) { return uint32_t{static_cast<uint8_t>(b[at + i])}; };
  return (byte(0) << 24) | (byte(1) << 16) | (byte(2) << 8) | byte(3);
}

uint8_t paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a);
  const int pb = std::abs(p - b);
  const int pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return static_cast<uint8_t>(a);
  return static_cast<uint8_t>(pb <= pc ? b : c);
}

// Undoes the row filters of `raw` (filter byte + row, per row) into out.rgb.
bool unfilter(const std::vector<uint8_t>& raw, DecodedPng& out) {
  const std::size_t row = std::size_t{out.width} * 3;
  out.rgb.assign(row * out.height, 0);
  for (uint32_t y = 0; y < out.height; ++y) {
    const uint8_t* in = raw.data() + y * (row + 1);
    uint8_t* line = out.rgb.data() + y * row;
    const uint8_t* above = y > 0 ? line - row : nullptr;
    for (std::size_t i = 0; i < row; ++i) {
      const int a = i >= 3 ? line[i - 3] : 0;
      const int b = above ? above[i] : 0;
      const int c = above && i >= 3 ? above[i - 3] : 0;
      int predictor = 0;
      switch (in[0]) {
        case 0: predictor = 0; break;
        case 1: predictor = a; break;
        case 2: predictor = b; break;
        case 3: predictor = (a + b) / 2; break;
        case 4: predictor = paeth(a, b, c); break;
        default: return false;
      }
      line[i] = static_cast<uint8_t>(in[1 + i] + predictor);
    }
  }
  return true;
}

}  // namespace

DecodedPng decode_png(const std::string& bytes) {
  DecodedPng out;
  static const char kSignature[8] = {'\x89', 'P', 'N', 'G', '\r', '\n', '\x1a', '\n'};
  if (bytes.size() < 8 || std::memcmp(bytes.data(), kSignature, 8) != 0) {
    out.error = "not a PNG (signature)";
    return out;
  }
  std::string idat;
  for (std::size_t at = 8; at + 12 <= bytes.size();) {
    const uint32_t length = get32(bytes, at);
    if (at + 12 + length > bytes.size()) break;
    const std::string type = bytes.substr(at + 4, 4);
    const auto* chunk = reinterpret_cast<const Bytef*>(bytes.data() + at + 4);
    if (static_cast<uint32_t>(::crc32(0L, chunk, length + 4)) != get32(bytes, at + 8 + length)) {
      out.error = "bad CRC in " + type;
      return out;
    }
    if (type == "IHDR") {
      out.width = get32(bytes, at + 8);
      out.height = get32(bytes, at + 12);
      if (bytes.compare(at + 16, 5, std::string("\x08\x02\x00\x00\x00", 5)) != 0) {
        out.error = "only 8-bit RGB, non-interlaced PNGs are read";
        return out;
      }
    } else if (type == "IDAT") {
      idat += bytes.substr(at + 8, length);
    } else if (type == "IEND") {
      std::vector<uint8_t> raw((std::size_t{out.width} * 3 + 1) * out.height);
      uLongf raw_size = raw.size();
      if (uncompress(raw.data(), &raw_size, reinterpret_cast<const Bytef*>(idat.data()), idat.size()) !=
              Z_OK ||
          raw_size != raw.size() || !unfilter(raw, out)) {
        out.error = "corrupt image data";
      }
      return out;
    }
    at += 12 + length;
  }
  out.error = "no IEND chunk";
  return out;
}

DecodedPng read_png(const std::string& path) {
  DecodedPng out = decode_png(read_file_bytes(path));
  if (!out.error.empty()) out.error = path + ": " + out.error;
  return out;
}

}  // namespace outcore::testing
