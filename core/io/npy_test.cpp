// Tests of the contract's .npy files: rays (N,6)/(N,8) float32, hits as
// numpy's structured dtype with 32-byte records, any-hit bools. Files are also
// written by hand byte for byte the way numpy.save does, so the reader is
// checked against numpy's format rather than against our own writer.
#include "core/io/npy.h"

#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::read_file_bytes;
using testing::TempDir;
using testing::write_text_file;

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr char kHitsDescr[] =
    "[('t_hit', '<f4'), ('geometry_id', '<u4'), ('primitive_id', '<u4'), ('u', '<f4'), ('v', '<f4'), "
    "('ng', '<f4', (3,))]";

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The header dict exactly as numpy.lib.format writes it: sorted keys, repr of
// each value, a trailing ", }", then numpy's spare space for growing axis 0.
std::string numpy_dict(const std::string& descr_repr, bool fortran, const std::string& shape_repr,
                       std::size_t first_dim_digits) {
  std::string dict = "{'descr': " + descr_repr + ", 'fortran_order': " + (fortran ? "True" : "False") +
                     ", 'shape': " + shape_repr + ", }";
  dict.append(21 - first_dim_digits, ' ');  // numpy's GROWTH_AXIS_MAX_DIGITS
  return dict;
}

// magic, version, little-endian header length (2 bytes for 1.0, 4 for 2.0/3.0),
// dict padded with spaces and a final '\n' so the data starts on a multiple of
// 64 bytes (numpy's ARRAY_ALIGN; numpy pads a full 64 when already aligned).
std::string numpy_header(const std::string& dict, int major = 1) {
  const std::size_t prefix = major == 1 ? 10 : 12;
  const std::size_t hlen = dict.size() + 1;
  const std::size_t pad = 64 - (prefix + hlen) % 64;
  const std::size_t total = hlen + pad;
  std::string out("\x93NUMPY", 6);
  out += static_cast<char>(major);
  out += '\0';
  for (std::size_t i = 0; i < prefix - 8; ++i) out += static_cast<char>((total >> (8 * i)) & 0xff);
  out += dict;
  out.append(pad, ' ');
  out += '\n';
  return out;
}

std::string float_bytes(const std::vector<float>& values) {
  std::string out(values.size() * sizeof(float), '\0');
  if (!values.empty()) std::memcpy(out.data(), values.data(), out.size());
  return out;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return std::move(s).str();
}

uint32_t u32_at(const std::string& bytes, std::size_t offset) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<uint32_t>(static_cast<uint8_t>(bytes[offset + i])) << (8 * i);
  return v;
}
float f32_at(const std::string& bytes, std::size_t offset) {
  return std::bit_cast<float>(u32_at(bytes, offset));
}

bool same_bits(const Ray& a, const Ray& b) {
  return std::memcmp(&a, &b, sizeof(Ray)) == 0;
}
bool same_bits(const Hit& a, const Hit& b) {
  return std::memcmp(&a, &b, sizeof(Hit)) == 0;
}

// A (rows, 6) float32 file exactly as numpy.save writes it.
std::string six_column_file(const std::vector<float>& values, int major = 1) {
  const std::size_t rows = values.size() / 6;
  const std::string n = std::to_string(rows);
  return numpy_header(numpy_dict("'<f4'", false, "(" + n + ", 6)", n.size()), major) + float_bytes(values);
}

std::vector<float> six_column_values() {
  return {0.0f,  0.5f,  -2.0f, 0.0f,  0.0f,  1.0f,     // 0
          1.25f, -3.5f, 4.0f,  2.0f,  -1.0f, 0.5f,     // 1
          -7.0f, 8.0f,  9.5f,  1e-3f, 1e3f,  -1e-7f};  // 2
}

void expect_six_column_rays(const std::vector<Ray>& rays, const std::vector<float>& values) {
  ASSERT_EQ(rays.size(), values.size() / 6);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const float* row = values.data() + 6 * i;
    EXPECT_EQ(rays[i].origin.x, row[0]) << i;
    EXPECT_EQ(rays[i].origin.y, row[1]) << i;
    EXPECT_EQ(rays[i].origin.z, row[2]) << i;
    EXPECT_EQ(rays[i].direction.x, row[3]) << i;
    EXPECT_EQ(rays[i].direction.y, row[4]) << i;
    EXPECT_EQ(rays[i].direction.z, row[5]) << i;
    EXPECT_EQ(rays[i].tnear, 0.0f) << i;
    EXPECT_EQ(rays[i].tfar, kInf) << i;
  }
}

// The file form and the in-memory form both reject `bytes`; the message
// names the file and mentions every one of `mentions`.
void expect_rays_rejected(const std::string& bytes, StatusCode code,
                          const std::vector<std::string>& mentions) {
  TempDir dir;
  const std::string path = dir.file("bad_rays.npy");
  write_text_file(path, bytes);
  const auto from_file = read_rays_npy(path);
  ASSERT_FALSE(from_file.ok()) << "accepted a bad rays file";
  EXPECT_EQ(from_file.status().code(), code) << from_file.status().to_string();
  EXPECT_TRUE(contains(from_file.status().message(), path)) << from_file.status().to_string();
  const auto from_memory = decode_rays_npy(bytes, "in_memory.npy");
  ASSERT_FALSE(from_memory.ok()) << "accepted a bad rays image";
  EXPECT_EQ(from_memory.status().code(), code) << from_memory.status().to_string();
  EXPECT_TRUE(contains(from_memory.status().message(), "in_memory.npy")) << from_memory.status().to_string();
  for (const std::string& m : mentions) {
    EXPECT_TRUE(contains(from_file.status().message(), m))
        << "no '" << m << "' in: " << from_file.status().message();
  }
}

// ---- rays -------------------------------------------------------------------------

TEST(NpyRays, EightColumnRoundTripIsBitExactWithNumpyLayout) {
  std::vector<Ray> rays(5);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const float f = static_cast<float>(i);
    rays[i].origin = {f, -f, 0.5f * f};
    rays[i].direction = {1.0f, f * 0.25f, -2.0f};
    rays[i].tnear = 0.125f * f;
    rays[i].tfar = i == 2 ? kInf : 10.0f + f;
  }
  rays[3].origin.x = std::numeric_limits<float>::quiet_NaN();  // stored as given, judged by the engine
  TempDir dir;
  const std::string path = dir.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(path, rays).ok());

  const auto back = read_rays_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  ASSERT_EQ(back->size(), rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) EXPECT_TRUE(same_bits((*back)[i], rays[i])) << "ray " << i;

  // What numpy would read: a C-order (5, 8) '<f4' array, data 64-byte aligned,
  // rows ox oy oz dx dy dz tnear tfar.
  const std::string bytes = read_bytes(path);
  const auto header = parse_npy_header(bytes, path);
  ASSERT_TRUE(header.ok()) << header.status().to_string();
  EXPECT_EQ(header->descr, "<f4");
  EXPECT_FALSE(header->fortran_order);
  EXPECT_EQ(header->shape, (std::vector<uint64_t>{5, 8}));
  EXPECT_EQ(header->data_offset % 64, 0u);
  EXPECT_EQ(bytes[header->data_offset - 1], '\n');
  ASSERT_EQ(bytes.size(), header->data_offset + 5 * 8 * sizeof(float));
  EXPECT_EQ(f32_at(bytes, header->data_offset + (4 * 8 + 1) * 4), -4.0f);  // oy of row 4
  EXPECT_EQ(f32_at(bytes, header->data_offset + (4 * 8 + 6) * 4), 0.5f);   // tnear of row 4
  EXPECT_EQ(f32_at(bytes, header->data_offset + (2 * 8 + 7) * 4), kInf);   // tfar of row 2
}

TEST(NpyRays, SixColumnNumpyFileGetsDefaultTnearAndTfar) {
  const std::vector<float> values = six_column_values();
  const std::string bytes = six_column_file(values);
  ASSERT_EQ(bytes.size() % 64, (3 * 6 * 4) % 64);  // header is a multiple of 64 bytes
  TempDir dir;
  const std::string path = dir.file("rays6.npy");
  write_text_file(path, bytes);
  const auto rays = read_rays_npy(path);
  ASSERT_TRUE(rays.ok()) << rays.status().to_string();
  expect_six_column_rays(*rays, values);

  const auto decoded = decode_rays_npy(bytes, "mem");
  ASSERT_TRUE(decoded.ok()) << decoded.status().to_string();
  expect_six_column_rays(*decoded, values);
}

TEST(NpyRays, OlderNumpyHeaderWithoutGrowthSpaceIsAccepted) {
  // numpy before 1.23 wrote no spare space; the dict is padded only to 64.
  const std::vector<float> values = six_column_values();
  const std::string bytes =
      numpy_header("{'descr': '<f4', 'fortran_order': False, 'shape': (3, 6), }") + float_bytes(values);
  const auto rays = decode_rays_npy(bytes, "old.npy");
  ASSERT_TRUE(rays.ok()) << rays.status().to_string();
  expect_six_column_rays(*rays, values);
}

TEST(NpyRays, NumpyFormatVersion2And3HeadersAreAccepted) {
  const std::vector<float> values = six_column_values();
  for (int major : {2, 3}) {
    const std::string bytes = six_column_file(values, major);
    ASSERT_EQ(bytes[6], static_cast<char>(major));
    ASSERT_EQ((bytes.size() - values.size() * 4) % 64, 0u);
    const auto rays = decode_rays_npy(bytes, "v2.npy");
    ASSERT_TRUE(rays.ok()) << "version " << major << ": " << rays.status().to_string();
    expect_six_column_rays(*rays, values);
  }
  // An (N,8) file in format 2.0 keeps its own tnear/tfar.
  const std::vector<float> row{1, 2, 3, 0, 0, -1, 0.5f, 7.0f};
  const auto eight = decode_rays_npy(
      numpy_header(numpy_dict("'<f4'", false, "(1, 8)", 1), 2) + float_bytes(row), "v2_8.npy");
  ASSERT_TRUE(eight.ok()) << eight.status().to_string();
  ASSERT_EQ(eight->size(), 1u);
  EXPECT_EQ((*eight)[0].tnear, 0.5f);
  EXPECT_EQ((*eight)[0].tfar, 7.0f);
  EXPECT_EQ((*eight)[0].direction.z, -1.0f);
}

TEST(NpyRays, ZeroRaysWork) {
  TempDir dir;
  const std::string path = dir.file("none.npy");
  ASSERT_TRUE(write_rays_npy(path, std::span<const Ray>()).ok());
  const auto back = read_rays_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_TRUE(back->empty());
  const auto header = parse_npy_header(read_bytes(path), path);
  ASSERT_TRUE(header.ok());
  EXPECT_EQ(header->shape, (std::vector<uint64_t>{0, 8}));

  const auto six = decode_rays_npy(six_column_file({}), "empty6.npy");
  ASSERT_TRUE(six.ok()) << six.status().to_string();
  EXPECT_TRUE(six->empty());
}

TEST(NpyRays, WrongDtypeIsRejectedNamingTheDtype) {
  const std::vector<float> values = six_column_values();
  // float64: same element count, twice the bytes.
  std::string f8 = numpy_header(numpy_dict("'<f8'", false, "(3, 6)", 1));
  f8.append(3 * 6 * 8, '\0');
  expect_rays_rejected(f8, StatusCode::kInvalidArgument, {"'<f8'", "float32"});
  const std::string i4 = numpy_header(numpy_dict("'<i4'", false, "(3, 6)", 1)) + float_bytes(values);
  expect_rays_rejected(i4, StatusCode::kInvalidArgument, {"'<i4'", "float32"});
  const std::string big = numpy_header(numpy_dict("'>f4'", false, "(3, 6)", 1)) + float_bytes(values);
  expect_rays_rejected(big, StatusCode::kInvalidArgument, {"'>f4'"});
}

TEST(NpyRays, FortranOrderIsRejected) {
  const std::string bytes =
      numpy_header(numpy_dict("'<f4'", true, "(3, 6)", 1)) + float_bytes(six_column_values());
  expect_rays_rejected(bytes, StatusCode::kInvalidArgument, {"Fortran"});
}

TEST(NpyRays, BadShapesAreRejectedNamingTheShape) {
  const std::vector<float> thirty(30, 1.0f);
  expect_rays_rejected(numpy_header(numpy_dict("'<f4'", false, "(6, 5)", 1)) + float_bytes(thirty),
                       StatusCode::kInvalidArgument, {"(6, 5)", "(N, 6)"});
  expect_rays_rejected(numpy_header(numpy_dict("'<f4'", false, "(30,)", 2)) + float_bytes(thirty),
                       StatusCode::kInvalidArgument, {"(30,)"});
  expect_rays_rejected(numpy_header(numpy_dict("'<f4'", false, "(5, 6, 1)", 1)) + float_bytes(thirty),
                       StatusCode::kInvalidArgument, {"(5, 6, 1)"});
  expect_rays_rejected(numpy_header(numpy_dict("'<f4'", false, "()", 0)) + float_bytes({1.0f}),
                       StatusCode::kInvalidArgument, {"shape"});
  expect_rays_rejected(numpy_header(numpy_dict("'<f4'", false, "(5, x)", 1)) + float_bytes(thirty),
                       StatusCode::kInvalidArgument, {"shape"});
}

TEST(NpyRays, TruncatedDataNamesExpectedAndActualBytes) {
  std::string bytes = six_column_file(six_column_values());
  bytes.resize(bytes.size() - 5);  // 72 bytes of data expected, 67 present
  expect_rays_rejected(bytes, StatusCode::kDataLoss, {"truncated", "72", "67"});
  // Header only, no data at all.
  const std::string whole = six_column_file(six_column_values());
  expect_rays_rejected(whole.substr(0, whole.size() - 72), StatusCode::kDataLoss,
                       {"truncated", "72", "has 0"});
}

TEST(NpyRays, TrailingBytesAreRejected) {
  std::string bytes = six_column_file(six_column_values()) + std::string(4, '\0');
  expect_rays_rejected(bytes, StatusCode::kInvalidArgument, {"4 bytes after"});
}

TEST(NpyRays, BadMagicIsRejected) {
  std::string bytes = six_column_file(six_column_values());
  bytes[5] = 'Z';
  expect_rays_rejected(bytes, StatusCode::kInvalidArgument, {"not a .npy file"});
  expect_rays_rejected("ox,oy,oz,dx,dy,dz\n0,0,0,0,0,1\n", StatusCode::kInvalidArgument, {"not a .npy file"});
  expect_rays_rejected("", StatusCode::kInvalidArgument, {"not a .npy file"});
}

TEST(NpyRays, UnsupportedVersionIsRejected) {
  std::string bytes = six_column_file(six_column_values());
  bytes[6] = 4;
  expect_rays_rejected(bytes, StatusCode::kInvalidArgument, {"version 4"});
}

TEST(NpyRays, TruncatedHeaderIsDataLoss) {
  const std::string whole = six_column_file(six_column_values());
  const std::size_t header_bytes = whole.size() - 72;
  for (std::size_t cut : {std::size_t{12}, std::size_t{40}, header_bytes - 1}) {
    SCOPED_TRACE("cut at " + std::to_string(cut));
    expect_rays_rejected(whole.substr(0, cut), StatusCode::kDataLoss, {"truncated", "header"});
  }
  const std::string v2 = six_column_file(six_column_values(), 2);
  expect_rays_rejected(v2.substr(0, 11), StatusCode::kDataLoss, {"truncated", "header"});
  expect_rays_rejected(v2.substr(0, 50), StatusCode::kDataLoss, {"truncated", "header"});
}

// A file whose magic is intact but which ends inside the fixed prefix (before
// the header length is complete) is truncated, not "bad magic".
TEST(NpyRays, TruncatedInsideTheVersionOrLengthFieldIsReportedAsTruncated) {
  const std::string whole = six_column_file(six_column_values());
  for (std::size_t cut : {std::size_t{7}, std::size_t{8}, std::size_t{9}}) {
    SCOPED_TRACE("cut at " + std::to_string(cut));
    expect_rays_rejected(whole.substr(0, cut), StatusCode::kDataLoss, {"truncated"});
  }
}

// A shape whose byte size overflows 64 bits must be an error, not a huge
// allocation (std::length_error / bad_alloc) or a wrapped size that matches.
TEST(NpyRays, ShapeWhoseByteSizeOverflowsIsRejected) {
  // 2^61 rows * 8 columns * 4 bytes = 2^66 bytes: wraps to 0 in uint64.
  const std::string huge = "2305843009213693952";
  const std::string bytes = numpy_header(numpy_dict("'<f4'", false, "(" + huge + ", 8)", huge.size()));
  EXPECT_NO_THROW({
    const auto rays = decode_rays_npy(bytes, "huge.npy");
    EXPECT_FALSE(rays.ok()) << "decoded " << rays->size() << " rays from a header-only file";
  });
}

TEST(NpyRays, MissingFileNamesThePath) {
  TempDir dir;
  const std::string path = dir.file("absent.npy");
  const auto rays = read_rays_npy(path);
  ASSERT_FALSE(rays.ok());
  EXPECT_TRUE(contains(rays.status().message(), path)) << rays.status().to_string();
}

// ---- hits -------------------------------------------------------------------------

TEST(NpyHits, HeaderIsNumpysStructuredDtypeWith32ByteRecords) {
  EXPECT_STREQ(kHitsNpyDescr, kHitsDescr);
  std::vector<Hit> hits(3);
  TempDir dir;
  const std::string path = dir.file("hits.npy");
  ASSERT_TRUE(write_hits_npy(path, hits).ok());
  const std::string bytes = read_bytes(path);
  ASSERT_GE(bytes.size(), 10u);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
  const std::size_t hlen =
      static_cast<uint8_t>(bytes[8]) | (static_cast<std::size_t>(static_cast<uint8_t>(bytes[9])) << 8);
  const std::size_t offset = 10 + hlen;
  EXPECT_EQ(offset % 64, 0u);
  ASSERT_EQ(bytes.size(), offset + 3 * 32);
  const std::string dict = bytes.substr(10, hlen);
  const std::string expected =
      std::string("{'descr': ") + kHitsDescr + ", 'fortran_order': False, 'shape': (3,), }";
  ASSERT_GE(dict.size(), expected.size() + 1);
  EXPECT_EQ(dict.substr(0, expected.size()), expected);
  EXPECT_EQ(dict.back(), '\n');
  EXPECT_EQ(dict.find_first_not_of(' ', expected.size()), dict.size() - 1)
      << "padding is not spaces: " << dict;
}

TEST(NpyHits, RecordFieldsSitAtNumpysOffsets) {
  Hit hit;
  hit.t = 1.5f;
  hit.geometry_id = 7;
  hit.primitive_id = 0x01020304u;
  hit.u = 0.25f;
  hit.v = 0.5f;
  hit.normal = {0.0f, 0.6f, -0.8f};
  const std::vector<Hit> hits{hit, Hit{}};
  TempDir dir;
  const std::string path = dir.file("hits.npy");
  ASSERT_TRUE(write_hits_npy(path, hits).ok());
  const std::string bytes = read_bytes(path);
  const auto header = parse_npy_header(bytes, path);
  ASSERT_TRUE(header.ok()) << header.status().to_string();
  EXPECT_EQ(header->shape, (std::vector<uint64_t>{2}));
  ASSERT_EQ(bytes.size(), header->data_offset + 64);
  const std::size_t o = header->data_offset;
  EXPECT_EQ(f32_at(bytes, o + 0), 1.5f);                // t_hit
  EXPECT_EQ(u32_at(bytes, o + 4), 7u);                  // geometry_id
  EXPECT_EQ(u32_at(bytes, o + 8), 0x01020304u);         // primitive_id
  EXPECT_EQ(static_cast<uint8_t>(bytes[o + 8]), 0x04);  // little-endian
  EXPECT_EQ(f32_at(bytes, o + 12), 0.25f);              // u
  EXPECT_EQ(f32_at(bytes, o + 16), 0.5f);               // v
  EXPECT_EQ(f32_at(bytes, o + 20), 0.0f);               // ng[0]
  EXPECT_EQ(f32_at(bytes, o + 24), 0.6f);               // ng[1]
  EXPECT_EQ(f32_at(bytes, o + 28), -0.8f);              // ng[2]
  // A miss: t_hit inf, ids 4294967295, zero normal.
  EXPECT_EQ(f32_at(bytes, o + 32), kInf);
  EXPECT_EQ(u32_at(bytes, o + 36), 4294967295u);
  EXPECT_EQ(u32_at(bytes, o + 40), 4294967295u);
  for (std::size_t k = 44; k < 64; k += 4) EXPECT_EQ(u32_at(bytes, o + k), 0u) << k;

  const auto back = read_hits_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  ASSERT_EQ(back->size(), 2u);
  EXPECT_TRUE(same_bits((*back)[0], hit));
  EXPECT_TRUE(same_bits((*back)[1], Hit{}));
  EXPECT_FALSE((*back)[1].is_hit());
}

TEST(NpyHits, ReadsNumpyWrittenHitsFile) {
  Hit hit;
  hit.t = 2.0f;
  hit.geometry_id = 1;
  hit.primitive_id = 99;
  hit.normal = {1, 0, 0};
  std::string data(32, '\0');
  std::memcpy(data.data(), &hit, 32);
  TempDir dir;
  const std::string path = dir.file("numpy_hits.npy");
  write_text_file(path, numpy_header(numpy_dict(kHitsDescr, false, "(1,)", 1)) + data);
  const auto back = read_hits_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  ASSERT_EQ(back->size(), 1u);
  EXPECT_TRUE(same_bits((*back)[0], hit));
}

TEST(NpyHits, ReadRejectsOtherArrays) {
  TempDir dir;
  const std::string path = dir.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(path, std::vector<Ray>(2)).ok());
  const auto hits = read_hits_npy(path);
  ASSERT_FALSE(hits.ok());
  EXPECT_TRUE(contains(hits.status().message(), path)) << hits.status().to_string();
  EXPECT_TRUE(contains(hits.status().message(), "<f4")) << hits.status().to_string();
}

TEST(NpyHits, ZeroHitsWork) {
  TempDir dir;
  const std::string path = dir.file("none.npy");
  ASSERT_TRUE(write_hits_npy(path, std::span<const Hit>()).ok());
  const std::string bytes = read_bytes(path);
  EXPECT_TRUE(contains(bytes, "'shape': (0,)")) << bytes;
  EXPECT_EQ(bytes.size() % 64, 0u);
  const auto back = read_hits_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_TRUE(back->empty());
}

// ---- bools ------------------------------------------------------------------------

TEST(NpyBools, RoundTripWithNumpyBoolDtype) {
  const std::vector<uint8_t> flags{1, 0, 1, 1, 0, 0, 1};
  TempDir dir;
  const std::string path = dir.file("flags.npy");
  ASSERT_TRUE(write_bools_npy(path, flags).ok());
  const std::string bytes = read_bytes(path);
  const auto header = parse_npy_header(bytes, path);
  ASSERT_TRUE(header.ok()) << header.status().to_string();
  EXPECT_EQ(header->descr, "|b1");
  EXPECT_EQ(header->shape, (std::vector<uint64_t>{7}));
  EXPECT_EQ(header->data_offset % 64, 0u);
  ASSERT_EQ(bytes.size(), header->data_offset + 7);
  EXPECT_EQ(bytes.substr(header->data_offset), std::string("\1\0\1\1\0\0\1", 7));
  EXPECT_TRUE(contains(bytes.substr(0, header->data_offset),
                       "{'descr': '|b1', 'fortran_order': False, 'shape': (7,), }"));

  const auto back = read_bools_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(*back, flags);
}

TEST(NpyBools, ZeroFlagsWorkAndOtherDtypesAreRejected) {
  TempDir dir;
  const std::string path = dir.file("none.npy");
  ASSERT_TRUE(write_bools_npy(path, std::span<const uint8_t>()).ok());
  const auto back = read_bools_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_TRUE(back->empty());

  const std::string rays = dir.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(rays, std::vector<Ray>(1)).ok());
  const auto wrong = read_bools_npy(rays);
  ASSERT_FALSE(wrong.ok());
  EXPECT_TRUE(contains(wrong.status().message(), rays)) << wrong.status().to_string();
}

// Issue 21, finding 7: a write that fails midway (disk full; here the
// process's file size limit, which fails write() with EFBIG the same way)
// must keep an earlier output whole and leave nothing else behind. Run in
// a forked child so the limit does not touch this process.
TEST(NpyWrite, AFailedWriteKeepsTheEarlierFileAndLeavesNoTemporary) {
  TempDir dir;
  const std::string path = dir.file("hits.npy");
  const std::string earlier = "an earlier run's output";
  write_text_file(path, earlier);
  const std::vector<Hit> hits(100000);  // 3.2 MB, far past the limit below
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const rlimit limit{64 * 1024, 64 * 1024};
    std::signal(SIGXFSZ, SIG_IGN);  // else the write kills the child instead of failing
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) ::_exit(3);
    const Status written = write_hits_npy(path, hits);
    ::_exit(written.ok() ? 1 : contains(written.message(), path) ? 0 : 2);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status)) << "the child died of signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: the write succeeded, 2: its error does not name the file";
  EXPECT_EQ(read_file_bytes(path), earlier) << "the earlier output must stay whole";
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    names.push_back(entry.path().filename().string());
  EXPECT_EQ(names, std::vector<std::string>{"hits.npy"}) << "no temporary left behind";

  // Without the limit the same write replaces the earlier file.
  ASSERT_TRUE(write_hits_npy(path, hits).ok());
  const auto back = read_hits_npy(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back->size(), hits.size());
  // A device cannot be renamed over: it is written in place, and stays a device.
  ASSERT_TRUE(write_hits_npy("/dev/null", hits).ok());
  EXPECT_TRUE(std::filesystem::is_character_file("/dev/null"));
  // A directory is an error naming it.
  const Status on_directory = write_hits_npy(dir.path(), hits);
  EXPECT_FALSE(on_directory.ok());
  EXPECT_TRUE(contains(on_directory.message(), dir.path())) << on_directory.to_string();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
