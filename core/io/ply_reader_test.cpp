#include "core/io/ply_reader.h"

#include <gtest/gtest.h>

#include <bit>
#include <charconv>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/io/reader_test_util.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;
using testing::write_text_file;

// Read with vertices in memory and again out of core; both must agree.
Expected<std::vector<Triangle>> read_ply(const std::string& path) {
  return testing::read_both_ways(open_ply_file, path);
}

// One scalar of a PLY body: its PLY type name and value.
struct Field {
  std::string type;
  double value;
};
using Item = std::vector<Field>;  // one element item, lists flattened (count, then items)

int integer_size(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32") return 4;
  ADD_FAILURE() << "not an integer type: " << type;
  return 0;
}

// Writes a PLY file: header lines (after "format"), then the body in the given
// format with an explicit byte order, so that the test does not depend on the
// host's.
void write_ply(const std::string& path, const std::string& format, const std::string& header_lines,
               const std::vector<Item>& items) {
  std::string text = "ply\nformat " + format + " 1.0\n" + header_lines + "end_header\n";
  const bool big_endian = format == "binary_big_endian";
  const auto append_bytes = [&](std::uint64_t bits, int size) {
    for (int i = 0; i < size; ++i) {
      const int shift = 8 * (big_endian ? size - 1 - i : i);
      text.push_back(static_cast<char>((bits >> shift) & 0xff));
    }
  };
  for (const Item& item : items) {
    for (std::size_t f = 0; f < item.size(); ++f) {
      const Field& field = item[f];
      const bool is_float = field.type == "float" || field.type == "float32";
      const bool is_double = field.type == "double" || field.type == "float64";
      if (format == "ascii") {
        char digits[64];
        std::to_chars_result written;
        if (is_float) {
          written = std::to_chars(digits, digits + sizeof(digits), static_cast<float>(field.value));
        } else if (is_double) {
          written = std::to_chars(digits, digits + sizeof(digits), field.value);
        } else {
          written = std::to_chars(digits, digits + sizeof(digits), static_cast<std::int64_t>(field.value));
        }
        text.append(digits, written.ptr);
        text += f + 1 < item.size() ? " " : "\n";
      } else if (is_float) {
        append_bytes(std::bit_cast<std::uint32_t>(static_cast<float>(field.value)), 4);
      } else if (is_double) {
        append_bytes(std::bit_cast<std::uint64_t>(field.value), 8);
      } else {
        // Two's complement bits; the low `size` bytes are the value in any integer type.
        const auto bits = static_cast<std::uint64_t>(static_cast<std::int64_t>(field.value));
        append_bytes(bits, integer_size(field.type));
      }
    }
  }
  write_text_file(path, text);
}

const char* const kFormats[] = {"ascii", "binary_little_endian", "binary_big_endian"};

// The small mesh of the mixed-type tests: 6 vertices, a triangle, a quad and a pentagon.
const double kVertexCoordinates[6][3] = {{0.1, 0.2, 0.3}, {1.5, -2.25, 3.0}, {1e-3, 7.0, -0.7},
                                         {4.0, 4.5, 5.0}, {-1.0, -1.0, 0.0}, {2.0 / 3.0, 1e5, 123.456}};
const std::vector<std::vector<int>> kFaces = {{0, 1, 2}, {2, 3, 4, 5}, {0, 1, 3, 4, 5}};

Vec3f mesh_vertex(int i) {
  return Vec3f(static_cast<float>(kVertexCoordinates[i][0]), static_cast<float>(kVertexCoordinates[i][1]),
               static_cast<float>(kVertexCoordinates[i][2]));
}

std::vector<Triangle> expected_mesh_triangles() {
  return {
      {mesh_vertex(0), mesh_vertex(1), mesh_vertex(2)},  // triangle
      {mesh_vertex(2), mesh_vertex(3), mesh_vertex(4)},  // quad, fanned from its first corner
      {mesh_vertex(2), mesh_vertex(4), mesh_vertex(5)},
      {mesh_vertex(0), mesh_vertex(1), mesh_vertex(3)},  // pentagon
      {mesh_vertex(0), mesh_vertex(3), mesh_vertex(4)},
      {mesh_vertex(0), mesh_vertex(4), mesh_vertex(5)},
  };
}

// The mesh with extra vertex properties (one a list), an extra element between
// vertices and faces, and extra face properties before and after the indices.
void write_mixed_mesh(const std::string& path, const std::string& format, const std::string& count_type,
                      const std::string& index_type) {
  const std::string header =
      "comment written by ply_reader_test\n"
      "obj_info mixed types\n"
      "element vertex 6\n"
      "property double x\n"
      "property float confidence\n"
      "property double y\n"
      "property list uchar int neighbours\n"
      "property double z\n"
      "property uchar red\n"
      "element material 2\n"
      "property list ushort float values\n"
      "property int id\n"
      "element face 3\n"
      "property uchar flags\n"
      "property list " +
      count_type + " " + index_type +
      " vertex_indices\n"
      "property list uchar float texcoord\n";
  std::vector<Item> items;
  for (int v = 0; v < 6; ++v) {
    items.push_back({{"double", kVertexCoordinates[v][0]},
                     {"float", 0.5 * v},
                     {"double", kVertexCoordinates[v][1]},
                     {"uchar", 2},
                     {"int", v + 1.0},
                     {"int", -7},
                     {"double", kVertexCoordinates[v][2]},
                     {"uchar", 200}});
  }
  items.push_back({{"ushort", 3}, {"float", 1}, {"float", 2}, {"float", 3}, {"int", 10}});
  items.push_back({{"ushort", 0}, {"int", -11}});
  for (const std::vector<int>& face : kFaces) {
    Item item = {{"uchar", 1}, {count_type, static_cast<double>(face.size())}};
    for (int index : face) item.push_back({index_type, static_cast<double>(index)});
    item.insert(item.end(), {{"uchar", 2}, {"float", 0.25}, {"float", 0.75}});
    items.push_back(item);
  }
  write_ply(path, format, header, items);
}

TEST(PlyReader, AsciiAndBothBinaryByteOrdersGiveIdenticalTrianglesForEveryIndexType) {
  const std::pair<const char*, const char*> count_and_index_types[] = {
      {"uchar", "int"}, {"uchar", "uint"}, {"uint8", "short"}, {"ushort", "ushort"},
      {"int", "uchar"}, {"char", "int32"}, {"uint", "uint32"}, {"short", "int16"},
  };
  TempDir dir;
  for (const char* format : kFormats) {
    for (const auto& [count_type, index_type] : count_and_index_types) {
      SCOPED_TRACE(std::string(format) + " " + count_type + " " + index_type);
      const std::string path = dir.file(std::string(format) + "_" + count_type + "_" + index_type + ".ply");
      write_mixed_mesh(path, format, count_type, index_type);
      auto triangles = read_ply(path);
      ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
      EXPECT_EQ(*triangles, expected_mesh_triangles());
    }
  }
}

TEST(PlyReader, ConvertsCoordinatesOfAnyNumericType) {
  TempDir dir;
  for (const char* format : kFormats) {
    SCOPED_TRACE(format);
    const std::string path = dir.file(std::string(format) + ".ply");
    write_ply(path, format,
              "element vertex 3\nproperty short x\nproperty uint y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_index\n",
              {{{"short", -3}, {"uint", 4000000000.0}, {"float", 0.1}},
               {{"short", 7}, {"uint", 0}, {"float", -2.5}},
               {{"short", 0}, {"uint", 1}, {"float", 1e-3}},
               {{"uchar", 3}, {"int", 2}, {"int", 1}, {"int", 0}}});
    auto triangles = read_ply(path);
    ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
    const std::vector<Triangle> expected = {{{0, 1, 1e-3f}, {7, 0, -2.5f}, {-3, 4000000000.0f, 0.1f}}};
    EXPECT_EQ(*triangles, expected);
  }
}

// Strips of 7 distinct vertices: restarts at -1 (also a trailing one), a strip
// too short to make a triangle, degenerate joins, and a second strip item.
TEST(PlyReader, ExpandsTriStripsWithRestartsAlternatingWindingAndDegenerates) {
  const auto vertex = [](int i) { return Vec3f(static_cast<float>(i), static_cast<float>(i * i), 1.0f); };
  const std::vector<Triangle> expected = {
      {vertex(0), vertex(1), vertex(2)},  // strip 0 1 2 3 4
      {vertex(2), vertex(1), vertex(3)}, {vertex(2), vertex(3), vertex(4)},
      {vertex(5), vertex(6), vertex(0)},  // strip 5 6 0 0 1: degenerates kept
      {vertex(0), vertex(6), vertex(0)}, {vertex(0), vertex(0), vertex(1)},
      {vertex(4), vertex(5), vertex(6)},  // the second item's strip
  };
  const std::vector<int> first_strips = {0, 1, 2, 3, 4, -1, 5, 6, 0, 0, 1, -1, 2, 3, -1};
  TempDir dir;
  for (const char* format : kFormats) {
    SCOPED_TRACE(format);
    std::vector<Item> items;
    for (int v = 0; v < 7; ++v) items.push_back({{"float", v * 1.0}, {"float", v * v * 1.0}, {"float", 1}});
    Item strips = {{"int", static_cast<double>(first_strips.size())}};
    for (int index : first_strips) strips.push_back({"int", static_cast<double>(index)});
    items.push_back(strips);
    items.push_back({{"int", 3}, {"int", 4}, {"int", 5}, {"int", 6}});
    const std::string path = dir.file(std::string(format) + ".ply");
    write_ply(path, format,
              "element vertex 7\nproperty float x\nproperty float y\nproperty float z\n"
              "element tristrips 2\nproperty list int int vertex_indices\n",
              items);
    auto triangles = read_ply(path);
    ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
    EXPECT_EQ(*triangles, expected);
  }
}

TEST(PlyReader, EmitsStripsAndFacesInElementOrder) {
  TempDir dir;
  const std::string path = dir.file("both.ply");
  write_text_file(path,
                  "ply\nformat ascii 1.0\n"
                  "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                  "element tristrips 1\nproperty list uchar int vertex_indices\n"
                  "element face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\n"
                  "0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
                  "4 0 1 2 3\n"
                  "3 3 2 1\n");
  auto triangles = read_ply(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  const Vec3f v0(0, 0, 0), v1(1, 0, 0), v2(0, 1, 0), v3(1, 1, 0);
  const std::vector<Triangle> expected = {{v0, v1, v2}, {v2, v1, v3}, {v3, v2, v1}};
  EXPECT_EQ(*triangles, expected);
}

TEST(PlyReader, AsciiToleratesCrlfBlankLinesAndNoFaces) {
  TempDir dir;
  const std::string path = dir.file("points.ply");
  write_text_file(path,
                  "ply\r\nformat ascii 1.0\r\ncomment points only\r\n"
                  "element vertex 2\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
                  "end_header\r\n"
                  "0 0 0\r\n\r\n1 2 3\r\n\r\n");
  auto triangles = read_ply(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  EXPECT_TRUE(triangles->empty());
}

TEST(PlyReader, MissingFileIsNotFoundAtOpen) {
  TempDir dir;
  const std::string path = dir.file("missing.ply");
  auto source = open_ply_file(path);
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(source.status().message(), path + ": No such file or directory");
}

struct BadHeaderCase {
  const char* text;
  const char* message;  // expected after "PATH:"
};

// Header problems are found by open_ply_file, before any streaming.
TEST(PlyReader, RejectsBadHeadersAtOpenNamingTheLine) {
  const std::string vertex = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string face = "element face 1\nproperty list uchar int vertex_indices\n";
  const std::pair<std::string, std::string> cases[] = {
      {"plx\nformat ascii 1.0\nend_header\n", "1: not a PLY file (the first line must be 'ply')"},
      {"ply\nformat binary_middle_endian 1.0\nend_header\n",
       "2: unsupported PLY format 'binary_middle_endian' (expected ascii, binary_little_endian or "
       "binary_big_endian)"},
      {"ply\nformat ascii 2.0\nend_header\n", "2: unsupported PLY version '2.0' (expected 1.0)"},
      {"ply\nformat ascii 1.0\ncomment ok\nelemnt vertex 3\nend_header\n",
       "4: unknown PLY header keyword 'elemnt'"},
      {"ply\nformat ascii 1.0\nelement vertex many\nend_header\n",
       "3: expected 'element NAME COUNT' with COUNT a non-negative integer, got 'element vertex many'"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float16 x\nend_header\n",
       "4: unknown property type 'float16'"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty list float int x\nend_header\n",
       "4: list count type must be an integer type, got 'float'"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "3: 'property' before any 'element'"},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nend_header\n",
       "3: element 'vertex' has no property 'z'"},
      {"ply\nformat ascii 1.0\n" + vertex + "element face 1\nproperty list uchar int corners\nend_header\n",
       "7: element 'face' has no list property 'vertex_indices' (or 'vertex_index')"},
      {"ply\nformat ascii 1.0\n" + vertex +
           "element tristrips 1\nproperty list uchar int vertex_index\nend_header\n",
       "7: element 'tristrips' has no list property 'vertex_indices'"},
      {"ply\nformat ascii 1.0\n" + vertex +
           "element face 1\nproperty list uchar float vertex_indices\nend_header\n",
       "7: property 'vertex_indices' of element 'face' must be a list of integers"},
      {"ply\nformat ascii 1.0\n" + face + vertex + "end_header\n",
       "3: element 'face' comes before element 'vertex'; vertices must precede the faces that use them"},
  };
  for (const auto& [text, message] : cases) {
    TempDir dir;
    const std::string path = dir.file("bad.ply");
    write_text_file(path, text);
    auto source = open_ply_file(path);
    ASSERT_FALSE(source.ok()) << text;
    EXPECT_EQ(source.status().code(), StatusCode::kInvalidArgument) << text;
    EXPECT_EQ(source.status().message(), path + ":" + message) << text;
  }

  TempDir dir;
  const std::string path = dir.file("unterminated.ply");
  write_text_file(path, "ply\nformat ascii 1.0\n" + vertex);
  auto source = open_ply_file(path);
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().message(), path + ": the PLY header has no 'end_header' line");
}

// Body problems surface from stream(): ascii ones name the line and the item.
TEST(PlyReader, RejectsBadAsciiBodiesNamingLineAndItem) {
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n";  // 9 lines
  const std::string vertices = "0 0 0\n1 0 0\n0 1 0\n";
  const std::pair<std::string, std::string> cases[] = {
      {"0 0 0\n1 0.5x 0\n0 1 0\n3 0 1 2\n3 0 1 2\n", ":11: vertex 1: expected a number (float), got '0.5x'"},
      {"0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n3 0 1 2\n",
       ":11: vertex 1: coordinate y is not finite in float32 (nan)"},
      {"0 0 0\n1 0 0\n0 1 1e39\n3 0 1 2\n3 0 1 2\n", ":12: vertex 2: value 1e39 is too large for type float"},
      {"0 0 0\n1 0\n0 1 0\n3 0 1 2\n3 0 1 2\n",
       ":11: vertex 1: line ends early (fewer values than the header declares)"},
      {"0 0 0\n1 0 0 5\n0 1 0\n3 0 1 2\n3 0 1 2\n",
       ":11: vertex 1: unexpected extra value '5' (more values than the header declares)"},
      {vertices + "3 0 1 2\n3 0 1 3\n", ":14: face 1: vertex index 3 out of range (3 vertices)"},
      {vertices + "3 0 1 2\n3 0 -1 2\n", ":14: face 1: vertex index -1 out of range (3 vertices)"},
      {vertices + "2 0 1\n3 0 1 2\n", ":13: face 0: has 2 corners; at least 3 are needed"},
      {vertices + "3 0 1 2\n3 0 1 x\n", ":14: face 1: expected an integer (int), got 'x'"},
      {vertices + "3 0 1 2\n3 0 1 2.0\n", ":14: face 1: expected an integer (int), got '2.0'"},
      {vertices + "3 0 1 2\n300 0 1 2\n", ":14: face 1: value 300 does not fit in type uchar"},
      {vertices + "3 0 1 2\n",
       ": unexpected end of file in element 'face' at index 1 (the header declares 2)"},
      {"0 0 0\n", ": unexpected end of file in element 'vertex' at index 1 (the header declares 3)"},
      {vertices + "3 0 1 2\n3 0 1 2\n3 0 1 2\n",
       ":15: unexpected data after the last element (the header declares fewer items)"},
  };
  for (const auto& [body, message] : cases) {
    TempDir dir;
    const std::string path = dir.file("bad.ply");
    write_text_file(path, header + body);
    auto triangles = read_ply(path);
    ASSERT_FALSE(triangles.ok()) << body;
    EXPECT_EQ(triangles.status().code(), StatusCode::kInvalidArgument) << body;
    EXPECT_EQ(triangles.status().message(), path + message) << body;
  }
}

// Binary ones name the element and item (there are no lines).
TEST(PlyReader, RejectsBadBinaryBodiesNamingElementAndIndex) {
  const std::string header =
      "element vertex 3\nproperty float x\nproperty float y\nproperty double z\n"
      "element extra 1\nproperty list uint short stuff\n"
      "element face 2\nproperty list uchar uint vertex_indices\n"
      "element tristrips 1\nproperty list int int vertex_indices\n";
  const Item good_face = {{"uchar", 3}, {"uint", 0}, {"uint", 1}, {"uint", 2}};
  const auto vertices = [](double z1) {
    return std::vector<Item>{{{"float", 0}, {"float", 0}, {"double", 0}},
                             {{"float", 1}, {"float", 0}, {"double", z1}},
                             {{"float", 0}, {"float", 1}, {"double", 0}}};
  };
  const auto file = [&](double z1, std::vector<Item> rest) {
    std::vector<Item> items = vertices(z1);
    items.insert(items.end(), rest.begin(), rest.end());
    return items;
  };
  const Item extra = {{"uint", 2}, {"short", -1}, {"short", 5}};
  const Item good_strip = {{"int", 4}, {"int", 0}, {"int", 1}, {"int", 2}, {"int", -1}};
  const std::pair<std::vector<Item>, std::string> cases[] = {
      {file(1e300, {extra, good_face, good_face, good_strip}),
       "vertex 1: coordinate z is not finite in float32 (1e+300)"},
      {file(std::numeric_limits<double>::quiet_NaN(), {extra, good_face, good_face, good_strip}),
       "vertex 1: coordinate z is not finite in float32 (nan)"},
      {file(0, {extra, good_face, {{"uchar", 3}, {"uint", 0}, {"uint", 999}, {"uint", 2}}, good_strip}),
       "face 1: vertex index 999 out of range (3 vertices)"},
      {file(0, {extra, good_face, {{"uchar", 1}, {"uint", 0}}, good_strip}),
       "face 1: has 1 corner; at least 3 are needed"},
      {file(0, {extra, good_face, good_face, {{"int", 4}, {"int", 0}, {"int", -2}, {"int", 1}, {"int", 2}}}),
       "tristrips 0: vertex index -2 out of range (3 vertices) at list position 1"},
      {file(0, {extra, good_face, good_face, {{"int", -3}}}), "tristrips 0: list has a negative length -3"},
      {file(0, {extra, good_face, {{"uchar", 3}, {"uint", 0}}}),
       "unexpected end of file in element 'face' at index 1 (the header declares 2)"},
      {file(0, {{{"uint", 3}, {"short", 1}}}),
       "unexpected end of file in element 'extra' at index 0 (the header declares 1)"},
      {file(0, {extra, good_face, good_face}),
       "unexpected end of file in element 'tristrips' at index 0 (the header declares 1)"},
  };
  for (const char* format : {"binary_little_endian", "binary_big_endian"}) {
    for (const auto& [items, message] : cases) {
      SCOPED_TRACE(std::string(format) + ": " + message);
      TempDir dir;
      const std::string path = dir.file("bad.ply");
      write_ply(path, format, header, items);
      auto triangles = read_ply(path);
      ASSERT_FALSE(triangles.ok());
      EXPECT_EQ(triangles.status().code(), StatusCode::kInvalidArgument);
      EXPECT_EQ(triangles.status().message(), path + ": " + message);
    }
  }
}

constexpr std::size_t kIgeaStripTriangles = 268686;

TEST(PlyReader, IgeaTriStripsExpandToEveryStripTriangle) {
  auto triangles = read_ply(testing::model_path("igea.ply"));
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  EXPECT_EQ(triangles->size(), kIgeaStripTriangles);
  for (const Triangle& t : *triangles) ASSERT_TRUE(t.is_finite());
}

TEST(PlyReader, StreamingTwiceYieldsIdenticalTriangles) {
  auto source = open_ply_file(testing::model_path("igea.ply"));
  ASSERT_TRUE(source.ok()) << source.status().to_string();
  std::vector<Triangle> passes[2];
  for (auto& pass : passes) {
    CallbackSink sink([&](std::span<const Triangle> batch) {
      pass.insert(pass.end(), batch.begin(), batch.end());
      return Status::Ok();
    });
    ASSERT_TRUE((*source)->stream(sink).ok());
  }
  EXPECT_EQ(passes[0].size(), kIgeaStripTriangles);
  EXPECT_EQ(passes[0], passes[1]);
}

TEST(PlyReader, SinkErrorStopsTheStreamAndIsReturnedUnchanged) {
  testing::expect_sink_error_returned_unchanged(open_ply_file, testing::model_path("igea.ply"));
}

// ---- out of core (vertex_spill.h); read_ply reads every file above both ways too ----

TEST(PlyReaderOutOfCore, OutOfRangeIndexNamesTheElementAndItemAndLeavesNoFiles) {
  TempDir dir;
  const std::string path = dir.file("bad.ply");
  write_ply(path, "binary_big_endian",
            "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element tristrips 1\nproperty list int int vertex_indices\n",
            {{{"float", 0}, {"float", 0}, {"float", 0}},
             {{"float", 1}, {"float", 0}, {"float", 0}},
             {{"float", 0}, {"float", 1}, {"float", 0}},
             {{"int", 6}, {"int", 0}, {"int", 1}, {"int", 2}, {"int", -1}, {"int", 0}, {"int", 3}}});
  EXPECT_EQ(testing::read_out_of_core_status(open_ply_file, path).message(),
            path + ": tristrips 0: vertex index 3 out of range (3 vertices) at list position 5");
}

// 3 vertices hold 36 bytes; the header's count decides.
TEST(PlyReaderOutOfCore, SpillsOnlyWhenTheHeadersVerticesExceedTheAllowance) {
  TempDir dir;
  const std::string path = dir.file("triangle.ply");
  write_text_file(path,
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                  "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  testing::expect_spills_only_beyond(open_ply_file, path, 36);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
