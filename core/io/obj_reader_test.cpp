#include "core/io/obj_reader.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/io/reader_test_util.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;
using testing::write_text_file;

// Read with vertices in memory and again out of core; both must agree.
Expected<std::vector<Triangle>> read_obj(const std::string& path) {
  return testing::read_both_ways(open_obj_file, path);
}

// The status of reading an OBJ holding text, and the path it was written to.
Status read_obj_text(const TempDir& dir, const std::string& text, std::string* path_out = nullptr) {
  const std::string path = dir.file("input.obj");
  write_text_file(path, text);
  if (path_out != nullptr) *path_out = path;
  return read_obj(path).status();
}

TEST(ObjReader, ReadsPolygonsCornerFormsNegativeIndicesAndIgnoresOtherStatements) {
  TempDir dir;
  const std::string path = dir.file("mixed.obj");
  write_text_file(path,
                  "# a comment\n"
                  "mtllib scene.mtl\n"
                  "o thing\n"
                  "v 0 0 0\n"
                  "v 1.5 0 0 1.0\n"  // w is ignored
                  "v\t1\t1\t0\r\n"   // tabs and CRLF
                  "v -2 +1 0.25\n"
                  "v 3e-1 2 -0\n"
                  "\n"
                  "vt 0 0\n"
                  "vn 0 0 1\n"
                  "vp 0.5\n"
                  "g group\n"
                  "s off\n"
                  "usemtl red\n"
                  "f 1 2 3\n"
                  "f 1/1 2/1 3/1 4/1\n"
                  "f 1//1 2//1 5//1 3//1 4//1 # a pentagon\n"
                  "f -5/1/1 -4/1/1 -1/1/1\n"
                  "l 1 2\n"
                  "p 1\n"
                  "unknown keyword here\n"
                  "v 4 4 4\n"
                  "f -1 1 2");  // no final newline
  auto triangles = read_obj(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();

  const Vec3f v1(0, 0, 0), v2(1.5f, 0, 0), v3(1, 1, 0), v4(-2, 1, 0.25f), v5(0.3f, 2, -0.0f), v6(4, 4, 4);
  const std::vector<Triangle> expected = {
      {v1, v2, v3},                              // triangle
      {v1, v2, v3}, {v1, v3, v4},                // quad, fanned from corner 1
      {v1, v2, v5}, {v1, v5, v3}, {v1, v3, v4},  // pentagon
      {v1, v2, v5},                              // -5 -4 -1 with 5 vertices defined
      {v6, v1, v2},                              // -1 is the vertex defined just above
  };
  EXPECT_EQ(*triangles, expected);
}

TEST(ObjReader, ZeroFacesStreamsNothing) {
  TempDir dir;
  const std::string path = dir.file("points.obj");
  write_text_file(path, "v 0 0 0\nv 1 0 0\nvn 0 0 1\n");
  auto triangles = read_obj(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  EXPECT_TRUE(triangles->empty());
}

TEST(ObjReader, MissingFileIsNotFoundAtOpen) {
  TempDir dir;
  const std::string path = dir.file("missing.obj");
  auto source = open_obj_file(path);
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(source.status().message(), path + ": No such file or directory");
}

TEST(ObjReader, DirectoryIsRejectedAtOpen) {
  TempDir dir;
  auto source = open_obj_file(dir.path());
  ASSERT_FALSE(source.ok());
  EXPECT_EQ(source.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(source.status().message().find(dir.path()), std::string::npos);
}

struct BadObjCase {
  const char* text;
  const char* message;  // expected after "PATH:"
};

TEST(ObjReader, RejectsBadInputWithPathAndLine) {
  const BadObjCase cases[] = {
      {"v 1 2 abc\n", "1: expected a number, got 'abc'"},
      {"v 1 2.5.1 3\n", "1: expected a number, got '2.5.1'"},
      {"v 1x 2 3\n", "1: expected a number, got '1x'"},
      {"v 1 2 3 w\n", "1: expected a number, got 'w'"},
      {"# header\n\nv 1 2\n", "3: vertex has 2 coordinates; expected 3 (v x y z)"},
      {"v\n", "1: vertex has 0 coordinates; expected 3 (v x y z)"},
      {"v 1 nan 3\n", "1: vertex coordinate y is not finite ('nan')"},
      {"v 1 2 -inf\n", "1: vertex coordinate z is not finite ('-inf')"},
      {"v 1e39 2 3\n", "1: vertex coordinate x = 1e39 is too large for float32"},
      {"v 0 0 0\nv 1 0 0\nf 1 2\n", "3: face has 2 corners; at least 3 are needed"},
      {"v 0 0 0\nf\n", "2: face has 0 corners; at least 3 are needed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "4: vertex index 0 is invalid (OBJ indices start at 1)"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "4: vertex index 4 out of range (3 vertices defined so far)"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n",
       "4: vertex index -4 out of range (3 vertices defined so far)"},
      {"v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", "3: vertex index 3 out of range (2 vertices defined so far)"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got 'x'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '3/'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3//\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '3//'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/1/\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '3/1/'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/a\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '3/a'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.0\n",
       "4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '3.0'"},
      {"v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 9\r\n",
       "4: vertex index 9 out of range (3 vertices defined so far)"},
  };
  for (const BadObjCase& bad : cases) {
    TempDir dir;
    std::string path;
    const Status status = read_obj_text(dir, bad.text, &path);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << bad.text;
    EXPECT_EQ(status.message(), path + ":" + bad.message) << bad.text;
  }
}

TEST(ObjReader, TinyCoordinatesUnderflowToZero) {
  TempDir dir;
  const std::string path = dir.file("tiny.obj");
  write_text_file(path, "v 1e-60 -1e-400 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  auto triangles = read_obj(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  ASSERT_EQ(triangles->size(), 1u);
  EXPECT_EQ((*triangles)[0].v0, Vec3f(0, 0, 0));
}

// More than the reader's 1 MiB buffer, CRLF endings, no final newline, and one
// face line longer than the buffer: lines that straddle refills must come out whole.
TEST(ObjReader, ReadsAcrossBufferBoundariesAndVeryLongLines) {
  TempDir dir;
  const std::string path = dir.file("large.obj");
  constexpr int kVertices = 60000;
  std::string text;
  for (int i = 0; i < kVertices; ++i) {
    text += "v " + std::to_string(i) + " " + std::to_string(i % 7) + " -" + std::to_string(i % 13) + "\r\n";
  }
  for (int i = 1; i + 2 <= kVertices; i += 3) {
    text += "f " + std::to_string(i) + " " + std::to_string(i + 1) + " " + std::to_string(i + 2) + "\r\n";
  }
  constexpr int kBigPolygonCorners = 300000;  // a ~2 MB line
  text += "f";
  for (int i = 0; i < kBigPolygonCorners; ++i) text.append(" ").append(std::to_string(1 + i % kVertices));
  ASSERT_GT(text.size(), std::size_t{2} << 20);
  write_text_file(path, text);

  auto triangles = read_obj(path);
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  const auto vertex = [](int i) {  // 1-based, as in the file
    return Vec3f(static_cast<float>(i - 1), static_cast<float>((i - 1) % 7),
                 -static_cast<float>((i - 1) % 13));
  };
  constexpr std::size_t kSmallFaces = kVertices / 3;
  ASSERT_EQ(triangles->size(), kSmallFaces + kBigPolygonCorners - 2);
  for (std::size_t f = 0; f < kSmallFaces; ++f) {
    const int first = static_cast<int>(3 * f + 1);
    ASSERT_EQ((*triangles)[f], (Triangle{vertex(first), vertex(first + 1), vertex(first + 2)})) << f;
  }
  const auto corner = [&](int j) { return vertex(1 + j % kVertices); };
  EXPECT_EQ((*triangles)[kSmallFaces], (Triangle{corner(0), corner(1), corner(2)}));
  EXPECT_EQ(triangles->back(),
            (Triangle{corner(0), corner(kBigPolygonCorners - 2), corner(kBigPolygonCorners - 1)}));
}

TEST(ObjReader, StanfordBunnyHas69451FiniteTriangles) {
  auto triangles = read_obj(testing::model_path("stanford-bunny.obj"));
  ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
  EXPECT_EQ(triangles->size(), 69451u);
  for (const Triangle& t : *triangles) ASSERT_TRUE(t.is_finite());
}

TEST(ObjReader, StreamingTwiceYieldsIdenticalTriangles) {
  auto source = open_obj_file(testing::model_path("stanford-bunny.obj"));
  ASSERT_TRUE(source.ok()) << source.status().to_string();
  std::vector<Triangle> passes[2];
  std::vector<std::size_t> batch_sizes[2];
  for (int pass = 0; pass < 2; ++pass) {
    CallbackSink sink([&](std::span<const Triangle> batch) {
      passes[pass].insert(passes[pass].end(), batch.begin(), batch.end());
      batch_sizes[pass].push_back(batch.size());
      return Status::Ok();
    });
    ASSERT_TRUE((*source)->stream(sink).ok());
  }
  EXPECT_EQ(passes[0].size(), 69451u);
  EXPECT_EQ(passes[0], passes[1]);
  EXPECT_EQ(batch_sizes[0], batch_sizes[1]);
  EXPECT_EQ(batch_sizes[0].front(), TriangleBatcher::kBatchSize);
}

TEST(ObjReader, SinkErrorStopsTheStreamAndIsReturnedUnchanged) {
  testing::expect_sink_error_returned_unchanged(open_obj_file, testing::model_path("stanford-bunny.obj"));
}

// ---- out of core (vertex_spill.h); read_obj reads every file above both ways too ----

TEST(ObjReaderOutOfCore, EveryModelMatchesTheInMemoryReadBitForBit) {
  for (const char* name :
       {"stanford-bunny.obj", "beast.obj", "fandisk.obj", "homer.obj", "spot.obj", "teapot.obj"}) {
    SCOPED_TRACE(name);
    auto triangles = read_obj(testing::model_path(name));
    ASSERT_TRUE(triangles.ok()) << triangles.status().to_string();
    EXPECT_GT(triangles->size(), 0u);
  }
}

TEST(ObjReaderOutOfCore, OutOfRangeIndexNamesTheLineAndLeavesNoFiles) {
  TempDir dir;
  const std::string path = dir.file("bad.obj");
  write_text_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 1 1 0\nf -1 -2 -5\n");
  EXPECT_EQ(testing::read_out_of_core_status(open_obj_file, path).message(),
            path + ":6: vertex index -5 out of range (4 vertices defined so far)");
}

// 3 vertices hold 36 bytes.
TEST(ObjReaderOutOfCore, SpillsOnlyWhenTheVerticesExceedTheAllowance) {
  TempDir dir;
  const std::string path = dir.file("triangle.obj");
  write_text_file(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  testing::expect_spills_only_beyond(open_obj_file, path, 36);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
