#include "core/util/png_writer.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

uint32_t get32(const std::vector<uint8_t>& b, std::size_t at) {
  return (uint32_t{b[at]} << 24) | (uint32_t{b[at + 1]} << 16) | (uint32_t{b[at + 2]} << 8) | b[at + 3];
}

struct Chunk {
  std::string type;
  std::vector<uint8_t> data;
};

// Splits a PNG into chunks, checking the signature, lengths and every CRC.
std::vector<Chunk> parse(const std::vector<uint8_t>& png) {
  static const uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<Chunk> chunks;
  EXPECT_GE(png.size(), 8u);
  EXPECT_EQ(std::memcmp(png.data(), kSignature, 8), 0) << "PNG signature";
  std::size_t at = 8;
  while (at + 12 <= png.size()) {
    const uint32_t length = get32(png, at);
    EXPECT_LE(at + 12 + length, png.size());
    if (at + 12 + length > png.size()) break;
    Chunk c;
    c.type.assign(reinterpret_cast<const char*>(png.data() + at + 4), 4);
    c.data.assign(png.begin() + at + 8, png.begin() + at + 8 + length);
    // Checked with zlib's own crc32, independently of png_crc32.
    const uint32_t crc = static_cast<uint32_t>(::crc32(0L, png.data() + at + 4, length + 4));
    EXPECT_EQ(get32(png, at + 8 + length), crc) << "CRC of " << c.type;
    chunks.push_back(std::move(c));
    at += 12 + length;
  }
  EXPECT_EQ(at, png.size()) << "trailing bytes";
  return chunks;
}

TEST(PngWriterTest, Crc32MatchesTheKnownValueOfIend) {
  const uint8_t iend[4] = {'I', 'E', 'N', 'D'};
  EXPECT_EQ(png_crc32(iend), 0xAE426082u);
  EXPECT_EQ(png_crc32(std::span<const uint8_t>()), 0u);
}

TEST(PngWriterTest, EncodesAnRgbImageThatDecodesBackExactly) {
  const uint32_t w = 37, h = 23;
  std::vector<uint8_t> rgb(w * h * 3);
  for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<uint8_t>((i * 7919) >> 3);
  auto png = encode_png(w, h, rgb);
  ASSERT_TRUE(png.ok()) << png.status().to_string();
  const auto chunks = parse(*png);
  ASSERT_EQ(chunks.size(), 3u);
  EXPECT_EQ(chunks[0].type, "IHDR");
  EXPECT_EQ(chunks[1].type, "IDAT");
  EXPECT_EQ(chunks[2].type, "IEND");
  ASSERT_EQ(chunks[0].data.size(), 13u);
  EXPECT_EQ(get32(chunks[0].data, 0), w);
  EXPECT_EQ(get32(chunks[0].data, 4), h);
  EXPECT_EQ(chunks[0].data[8], 8);  // bit depth
  EXPECT_EQ(chunks[0].data[9], 2);  // truecolour
  // Inflate and undo the filters.
  std::vector<uint8_t> raw((w * 3 + 1) * h);
  uLongf raw_size = raw.size();
  ASSERT_EQ(uncompress(raw.data(), &raw_size, chunks[1].data.data(), chunks[1].data.size()), Z_OK);
  ASSERT_EQ(raw_size, raw.size());
  std::vector<uint8_t> decoded(w * h * 3);
  for (uint32_t y = 0; y < h; ++y) {
    const uint8_t* line = raw.data() + y * (w * 3 + 1);
    ASSERT_EQ(line[0], 2) << "filter Up";
    for (uint32_t i = 0; i < w * 3; ++i) {
      const uint8_t above = y ? decoded[(y - 1) * w * 3 + i] : 0;
      decoded[y * w * 3 + i] = static_cast<uint8_t>(line[1 + i] + above);
    }
  }
  EXPECT_EQ(decoded, rgb);
}

TEST(PngWriterTest, RejectsBadSizesAndWritesFiles) {
  std::vector<uint8_t> rgb(4 * 4 * 3, 200);
  EXPECT_FALSE(encode_png(0, 4, {}).ok());
  EXPECT_FALSE(encode_png(4, 4, std::span<const uint8_t>(rgb.data(), rgb.size() - 1)).ok());
  EXPECT_FALSE(encode_png(1u << 20, 1, rgb).ok());
  testing::TempDir dir;
  ASSERT_TRUE(write_png(dir.file("a.png"), 4, 4, rgb).ok());
  std::ifstream in(dir.file("a.png"), std::ios::binary);
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(bytes, *encode_png(4, 4, rgb));
  const Status bad = write_png(dir.file("missing/a.png"), 4, 4, rgb);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("missing/a.png"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
