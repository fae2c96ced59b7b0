// The .npz mesh input: every accepted dtype and order gives back exactly the
// triangles its arrays describe, in row order (degenerate ones kept); every
// malformed archive is an error naming the file, the member and the row.
#include "core/io/npz_mesh_reader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "core/gen/gen_test_util.h"
#include "core/io/file_source.h"
#include "core/io/npz_test_util.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::Entry;
using testing::npy_image;
using testing::raw_bytes;
using testing::TempDir;
using testing::zip_of;

// A unit square of two triangles and a third, degenerate one (repeated index).
const std::vector<float> kSquare = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
const std::vector<int32_t> kSquareTriangles = {0, 1, 2, 0, 2, 3, 1, 1, 3};

std::vector<Triangle> square_triangles() {
  const auto v = [](int i) { return Vec3f(kSquare[3 * i], kSquare[3 * i + 1], kSquare[3 * i + 2]); };
  std::vector<Triangle> out;
  for (std::size_t t = 0; t < kSquareTriangles.size(); t += 3)
    out.push_back({v(kSquareTriangles[t]), v(kSquareTriangles[t + 1]), v(kSquareTriangles[t + 2])});
  return out;
}

std::string archive(const std::string& vertices, const std::string& triangles, bool deflate = false) {
  return zip_of({{"vertices.npy", vertices, deflate}, {"triangles.npy", triangles, deflate}});
}

std::string square_archive() {
  return archive(npy_image("<f4", "(4, 3)", raw_bytes(kSquare)),
                 npy_image("<i4", "(3, 3)", raw_bytes(kSquareTriangles)));
}

std::vector<Triangle> read_all(const std::string& bytes, const std::string& name = "mesh.npz") {
  auto source = decode_npz_mesh(bytes, name);
  EXPECT_TRUE(source.ok()) << source.status().to_string();
  if (!source.ok()) return {};
  auto first = read_all(**source);
  EXPECT_TRUE(first.ok()) << first.status().to_string();
  auto second = read_all(**source);
  EXPECT_TRUE(second.ok() && first.ok() && *first == *second) << "a second stream() differs";
  return first.ok() ? *first : std::vector<Triangle>{};
}

// The error decoding `bytes` gives, which must name mesh.npz and every one of `mentions`.
void expect_error(const std::string& bytes, StatusCode code, const std::vector<std::string>& mentions) {
  const auto source = decode_npz_mesh(bytes, "mesh.npz");
  ASSERT_FALSE(source.ok()) << mentions.front();
  EXPECT_EQ(source.status().code(), code) << source.status().to_string();
  EXPECT_TRUE(contains(source.status().message(), "mesh.npz")) << source.status().to_string();
  for (const std::string& m : mentions)
    EXPECT_TRUE(contains(source.status().message(), m))
        << "no '" << m << "' in " << source.status().to_string();
}

TEST(NpzMeshReader, RowsBecomeTrianglesInOrderWithDegeneratesKept) {
  const std::vector<Triangle> got = read_all(square_archive());
  EXPECT_EQ(got, square_triangles());
  ASSERT_EQ(got.size(), 3u);
  EXPECT_TRUE(got[2].is_degenerate());  // row 2 keeps its primitive id
}

TEST(NpzMeshReader, EveryAcceptedDtypeAndOrderGivesTheSameTriangles) {
  const std::vector<double> wide(kSquare.begin(), kSquare.end());
  const std::vector<int64_t> long_indices(kSquareTriangles.begin(), kSquareTriangles.end());
  const std::vector<uint32_t> unsigned_indices(kSquareTriangles.begin(), kSquareTriangles.end());
  const std::vector<uint64_t> long_unsigned(kSquareTriangles.begin(), kSquareTriangles.end());
  // Column-major copies (what numpy.save writes for a transposed (3, N) array).
  std::vector<float> fortran_vertices(12);
  std::vector<int32_t> fortran_triangles(9);
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 3; ++c) fortran_vertices[c * 4 + r] = kSquare[r * 3 + c];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) fortran_triangles[c * 3 + r] = kSquareTriangles[r * 3 + c];
  const std::string f4 = npy_image("<f4", "(4, 3)", raw_bytes(kSquare));
  const std::string i4 = npy_image("<i4", "(3, 3)", raw_bytes(kSquareTriangles));
  const std::vector<std::pair<std::string, std::string>> cases = {
      {npy_image("<f8", "(4, 3)", raw_bytes(wide)), i4},
      {f4, npy_image("<i8", "(3, 3)", raw_bytes(long_indices))},
      {f4, npy_image("<u4", "(3, 3)", raw_bytes(unsigned_indices))},
      {f4, npy_image("<u8", "(3, 3)", raw_bytes(long_unsigned))},
      {npy_image("<f4", "(4, 3)", raw_bytes(fortran_vertices), true),
       npy_image("<i4", "(3, 3)", raw_bytes(fortran_triangles), true)},
  };
  for (std::size_t k = 0; k < cases.size(); ++k) {
    SCOPED_TRACE("case " + std::to_string(k));
    EXPECT_EQ(read_all(archive(cases[k].first, cases[k].second)), square_triangles());
    EXPECT_EQ(read_all(archive(cases[k].first, cases[k].second, /*deflate=*/true)), square_triangles());
  }
}

TEST(NpzMeshReader, Float64VerticesAreRoundedToNearestFloat32) {
  const std::vector<double> v = {0.1, 1.0 / 3.0, -2.7, 1e-3, 5, 6, 7, 8, 9};
  const std::vector<int32_t> t = {0, 1, 2};
  const auto got =
      read_all(archive(npy_image("<f8", "(3, 3)", raw_bytes(v)), npy_image("<i4", "(1, 3)", raw_bytes(t))));
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].v0, Vec3f(0.1f, static_cast<float>(1.0 / 3.0), -2.7f));
  EXPECT_EQ(got[0].v1, Vec3f(1e-3f, 5, 6));
}

TEST(NpzMeshReader, OtherMembersAreIgnoredAndAnEmptyMeshHasNoTriangles) {
  const std::string with_extra =
      zip_of({{"colors.npy", npy_image("|u1", "(4, 3)", std::string(12, '\x7f'))},
              {"vertices.npy", npy_image("<f4", "(4, 3)", raw_bytes(kSquare))},
              {"triangles.npy", npy_image("<i4", "(3, 3)", raw_bytes(kSquareTriangles))}});
  EXPECT_EQ(read_all(with_extra), square_triangles());
  EXPECT_TRUE(read_all(archive(npy_image("<f4", "(0, 3)", ""), npy_image("<i8", "(0, 3)", ""))).empty());
}

TEST(NpzMeshReader, MissingMembersAreNamedWithWhatTheArchiveHas) {
  const std::string f4 = npy_image("<f4", "(4, 3)", raw_bytes(kSquare));
  expect_error(zip_of({{"vertices.npy", f4}, {"faces.npy", f4}}), StatusCode::kInvalidArgument,
               {"no member 'triangles'", "faces, vertices"});
  expect_error(zip_of({{"points.npy", f4}}), StatusCode::kInvalidArgument,
               {"no member 'vertices'", "points"});
}

TEST(NpzMeshReader, WrongDtypesAndShapesAreNamedByMember) {
  const std::string f4 = npy_image("<f4", "(4, 3)", raw_bytes(kSquare));
  const std::string i4 = npy_image("<i4", "(3, 3)", raw_bytes(kSquareTriangles));
  expect_error(archive(npy_image("<i4", "(4, 3)", raw_bytes(kSquareTriangles) + std::string(12, '\0')), i4),
               StatusCode::kInvalidArgument, {"member vertices", "'<i4'", "float32 or float64"});
  expect_error(archive(f4, npy_image("<f4", "(3, 3)", raw_bytes(std::vector<float>(9)))),
               StatusCode::kInvalidArgument, {"member triangles", "'<f4'", "int32"});
  expect_error(archive(f4, npy_image("<i2", "(3, 3)", std::string(18, '\0'))), StatusCode::kInvalidArgument,
               {"member triangles", "'<i2'"});
  expect_error(archive(f4, npy_image(">i4", "(3, 3)", std::string(36, '\0'))), StatusCode::kInvalidArgument,
               {"member triangles", "'>i4'"});
  expect_error(archive(npy_image("<f4", "(6, 2)", raw_bytes(kSquare)), i4), StatusCode::kInvalidArgument,
               {"member vertices", "shape (6, 2)", "(N, 3)"});
  expect_error(archive(npy_image("<f4", "(12,)", raw_bytes(kSquare)), i4), StatusCode::kInvalidArgument,
               {"member vertices", "shape (12,)"});
  expect_error(archive(f4, npy_image("<i4", "(1, 3, 3)", raw_bytes(kSquareTriangles))),
               StatusCode::kInvalidArgument, {"member triangles", "shape (1, 3, 3)"});
  // A member whose data is shorter than its shape says.
  expect_error(archive(npy_image("<f4", "(5, 3)", raw_bytes(kSquare)), i4), StatusCode::kDataLoss,
               {"member vertices", "truncated"});
  expect_error("not a zip at all, but long enough to look for a directory", StatusCode::kInvalidArgument,
               {"not a .npz"});
}

TEST(NpzMeshReader, IndicesOutOfRangeNameTheTriangleRow) {
  const std::string f4 = npy_image("<f4", "(4, 3)", raw_bytes(kSquare));
  const std::vector<int32_t> too_large = {0, 1, 2, 0, 2, 3, 3, 4, 0};
  expect_error(archive(f4, npy_image("<i4", "(3, 3)", raw_bytes(too_large))), StatusCode::kInvalidArgument,
               {"member triangles: row 2: vertex index 4 out of range (4 vertices)"});
  const std::vector<int64_t> negative = {0, 1, -1};
  expect_error(archive(f4, npy_image("<i8", "(1, 3)", raw_bytes(negative))), StatusCode::kInvalidArgument,
               {"member triangles: row 0: vertex index -1 out of range"});
  const std::vector<uint64_t> huge = {0, 1, 2, 0, 1, uint64_t{1} << 40};
  expect_error(archive(f4, npy_image("<u8", "(2, 3)", raw_bytes(huge))), StatusCode::kInvalidArgument,
               {"row 1: vertex index 1099511627776 out of range"});
}

TEST(NpzMeshReader, NonFiniteAndTooLargeCoordinatesNameTheVertexRowAndAxis) {
  const std::string i4 = npy_image("<i4", "(3, 3)", raw_bytes(kSquareTriangles));
  const auto with = [&](int row, int axis, double value) {
    std::vector<double> v(kSquare.begin(), kSquare.end());
    v[row * 3 + axis] = value;
    return archive(npy_image("<f8", "(4, 3)", raw_bytes(v)), i4);
  };
  expect_error(with(1, 1, std::nan("")), StatusCode::kInvalidArgument,
               {"member vertices: row 1: coordinate y is not finite in float32"});
  expect_error(with(3, 0, -std::numeric_limits<double>::infinity()), StatusCode::kInvalidArgument,
               {"row 3: coordinate x is not finite in float32 (-inf)"});
  expect_error(with(2, 2, 1e39), StatusCode::kInvalidArgument,
               {"row 2: coordinate z is not finite in float32 (1e+39)"});
  expect_error(with(0, 2, -6e11), StatusCode::kInvalidArgument,
               {"row 0: coordinate z = -6e+11 is beyond", "5.5e11"});
  // The limit itself is accepted.
  EXPECT_EQ(read_all(with(0, 0, 0x1p39)).size(), 3u);
}

TEST(NpzMeshReader, AMeshLargerThanItsMemoryAllowanceIsRefusedNamingIt) {
  HeldMemoryLimit held;
  held.bytes = 4 * 12 + 3 * 12 - 1;  // one byte short of the square's vertices and triangles
  held.origin = "the test's limit";
  const auto refused = decode_npz_mesh(square_archive(), "mesh.npz", held);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kResourceExhausted);
  EXPECT_TRUE(contains(refused.status().message(), "mesh.npz")) << refused.status().to_string();
  EXPECT_TRUE(contains(refused.status().message(), "the test's limit")) << refused.status().to_string();
  held.bytes += 1;
  const auto accepted = decode_npz_mesh(square_archive(), "mesh.npz", held);
  ASSERT_TRUE(accepted.ok()) << accepted.status().to_string();
  EXPECT_EQ((*accepted)->held_memory_bytes(), 4u * 12 + 3 * 12);
  EXPECT_TRUE((*accepted)->cheap_to_restream());
}

TEST(NpzMeshReader, FilesAreOpenedByExtensionAndOnlyWhenRegular) {
  TempDir dir;
  const std::string path = dir.file("Scan.NPZ");
  testing::write_text_file(path, square_archive());
  auto source = open_triangle_file(path);
  ASSERT_TRUE(source.ok()) << source.status().to_string();
  EXPECT_EQ((*source)->description(), path);
  const auto got = read_all(**source);
  ASSERT_TRUE(got.ok()) << got.status().to_string();
  EXPECT_EQ(*got, square_triangles());

  const auto missing = open_triangle_file(dir.file("nowhere.npz"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(contains(missing.status().message(), dir.file("nowhere.npz")));
  std::filesystem::create_directory(dir.file("folder.npz"));
  const auto folder = open_triangle_file(dir.file("folder.npz"));
  ASSERT_FALSE(folder.ok());
  EXPECT_TRUE(contains(folder.status().message(), "a directory")) << folder.status().to_string();
  // Errors from the file name it, the member and the row.
  const std::vector<int32_t> bad = {0, 1, 9};
  testing::write_text_file(path, archive(npy_image("<f4", "(4, 3)", raw_bytes(kSquare)),
                                         npy_image("<i4", "(1, 3)", raw_bytes(bad))));
  const auto failed = open_triangle_file(path);
  ASSERT_FALSE(failed.ok());
  EXPECT_TRUE(contains(failed.status().message(), path + ", member triangles: row 0: vertex index 9"))
      << failed.status().to_string();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
