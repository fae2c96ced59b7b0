// PNG encoding of 8-bit RGB images (plots such as `outcore cache-sim --png`,
// `outcore render`'s pictures): IHDR, one zlib-compressed IDAT (filter "Up"
// on every row, which turns a plot's repeated rows into zeros), IEND; each
// chunk with its CRC.
//
// Thread-safety: functions of their arguments only.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

// rgb: width × height × 3 bytes, rows top to bottom. INVALID_ARGUMENT for a
// zero or oversized dimension or a buffer of the wrong size.
Expected<std::vector<uint8_t>> encode_png(uint32_t width, uint32_t height, std::span<const uint8_t> rgb);
// encode_png, then writes the file atomically (core/util/atomic_file.h: an
// earlier file at `path` stays whole if the write fails; IO_ERROR naming it).
Status write_png(const std::string& path, uint32_t width, uint32_t height, std::span<const uint8_t> rgb);

// CRC-32 as PNG (and zlib) define it, over `bytes` (for tests).
uint32_t png_crc32(std::span<const uint8_t> bytes);

}  // namespace outcore
