// Subtree files: a written file reads back as the same brick; a missing file
// is absent; truncation at any point, a flipped byte, a wrong magic or
// checksum are corrupt; another format version is a version rejection; a
// valid file for another key (brick id, source checksum, triangle count,
// structure options) is stale. None of them crashes or yields an accel.
#include "core/cache/subtree_file.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/bvh_brick_serializer.h"
#include "core/util/checksum.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;

// Rewrites the trailing checksum so that only the edited field is wrong.
std::string with_fixed_checksum(std::string bytes) {
  const uint64_t sum = checksum64(bytes.data(), bytes.size() - sizeof(uint64_t));
  std::memcpy(bytes.data() + bytes.size() - sizeof(uint64_t), &sum, sizeof(sum));
  return bytes;
}

class SubtreeFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    BrickData brick = accel_test::load_brick_from("gen:torus?nu=24&nv=12");
    brick.brick_id = 3;
    accel_ = std::move(BvhBrickAccel::build(std::move(brick), config_)).value();
    key_ = {3, 0x1234abcd5678ef00ull, accel_->triangle_count(), serializer_.structure_key()};
    path_ = dir_.file("brick.subtree");
    uint64_t bytes = 0;
    const Status written = write_subtree_file(path_, key_, serializer_, *accel_, &bytes);
    ASSERT_TRUE(written.ok()) << written.to_string();
    EXPECT_EQ(bytes, fs::file_size(path_));
    bytes_ = testing::read_file_bytes(path_);
  }

  SubtreeReadResult read_edited(const std::string& bytes, const SubtreeKey& key) {
    testing::write_text_file(dir_.file("edited.subtree"), bytes);
    return read_subtree_file(dir_.file("edited.subtree"), key, serializer_);
  }
  SubtreeReadResult read_edited(const std::string& bytes) { return read_edited(bytes, key_); }

  testing::TempDir dir_;
  BvhBrickConfig config_;
  BvhBrickSerializer serializer_{config_};
  std::unique_ptr<BvhBrickAccel> accel_;
  SubtreeKey key_;
  std::string path_;
  std::string bytes_;
};

TEST_F(SubtreeFileTest, ReadsBackTheSameBrick) {
  SubtreeReadResult read = read_subtree_file(path_, key_, serializer_);
  ASSERT_EQ(read.rejection, SubtreeRejection::kNone) << read.message;
  ASSERT_NE(read.accel, nullptr);
  EXPECT_EQ(read.file_bytes, bytes_.size());
  EXPECT_EQ(read.accel->memory_bytes(), accel_->memory_bytes());
  const auto rays = accel_test::rays_from_outside(
      accel_test::bounds_of(accel_test::load_brick_from("gen:torus?nu=24&nv=12")), 500, 5);
  std::vector<Hit> a(rays.size()), b(rays.size());
  accel_->intersect(accel_test::all_ids(rays.size()), rays.data(), a.data());
  read.accel->intersect(accel_test::all_ids(rays.size()), rays.data(), b.data());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)), 0);
  EXPECT_EQ(bytes_.substr(0, 8), std::string(kSubtreeMagic, 8));
}

TEST_F(SubtreeFileTest, MissingFileIsAbsent) {
  const SubtreeReadResult read = read_subtree_file(dir_.file("none.subtree"), key_, serializer_);
  EXPECT_EQ(read.rejection, SubtreeRejection::kAbsent);
  EXPECT_EQ(read.accel, nullptr);
}

TEST_F(SubtreeFileTest, TruncatedAnywhereIsCorrupt) {
  for (std::size_t cut = 0; cut < bytes_.size(); cut += std::max<std::size_t>(1, bytes_.size() / 97)) {
    const SubtreeReadResult read = read_edited(bytes_.substr(0, cut));
    EXPECT_EQ(read.rejection, SubtreeRejection::kCorrupt) << "cut at " << cut << ": " << read.message;
    EXPECT_EQ(read.accel, nullptr);
  }
  EXPECT_EQ(read_edited(bytes_.substr(0, bytes_.size() - 1)).rejection, SubtreeRejection::kCorrupt);
}

TEST_F(SubtreeFileTest, FlippedBytesWrongMagicAndWrongChecksumAreCorrupt) {
  for (const std::size_t at : {std::size_t{20}, bytes_.size() / 3, bytes_.size() / 2, bytes_.size() - 9}) {
    std::string bad = bytes_;
    bad[at] ^= 0x40;
    const SubtreeReadResult read = read_edited(bad);
    EXPECT_EQ(read.rejection, SubtreeRejection::kCorrupt) << "byte " << at;
    EXPECT_NE(read.message.find("checksum"), std::string::npos) << read.message;
  }
  std::string magic = bytes_;
  magic[0] = 'X';
  EXPECT_EQ(read_edited(magic).rejection, SubtreeRejection::kCorrupt);
  std::string checksum = bytes_;
  checksum.back() ^= 1;
  EXPECT_EQ(read_edited(checksum).rejection, SubtreeRejection::kCorrupt);
  // A payload the serialiser refuses, behind a right checksum: corrupt, too.
  std::string payload = bytes_;
  payload.insert(payload.size() - sizeof(uint64_t), "junk");
  const SubtreeReadResult read = read_edited(with_fixed_checksum(payload));
  EXPECT_EQ(read.rejection, SubtreeRejection::kCorrupt) << read.message;
  EXPECT_NE(read.message.find("after the tree"), std::string::npos) << read.message;
}

TEST_F(SubtreeFileTest, AnotherFormatVersionIsAVersionRejection) {
  std::string other = bytes_;
  const uint32_t version = kSubtreeFormatVersion + 1;
  std::memcpy(other.data() + 8, &version, sizeof(version));
  const SubtreeReadResult read = read_edited(with_fixed_checksum(other));
  EXPECT_EQ(read.rejection, SubtreeRejection::kVersion);
  EXPECT_NE(read.message.find("version " + std::to_string(version)), std::string::npos) << read.message;
}

TEST_F(SubtreeFileTest, AnotherKeyIsStale) {
  std::vector<SubtreeKey> others(4, key_);
  others[0].brick_id = 4;
  others[1].source_checksum ^= 1;  // the brick was repacked, or another store
  others[2].triangle_count += 1;
  BvhBrickConfig mt;
  mt.triangle_test = TriangleTest::kMt;
  others[3].structure_key = BvhBrickSerializer(mt).structure_key();
  for (const SubtreeKey& other : others) {
    const SubtreeReadResult read = read_subtree_file(path_, other, serializer_);
    EXPECT_EQ(read.rejection, SubtreeRejection::kStale) << read.message;
    EXPECT_EQ(read.accel, nullptr);
    EXPECT_NE(read.message.find("wanted"), std::string::npos) << read.message;
  }
}

TEST_F(SubtreeFileTest, WritingOverAnExistingFileFails) {
  // The tier writes temporary files that must be new; an existing name is an error.
  EXPECT_FALSE(write_subtree_file(path_, key_, serializer_, *accel_, nullptr).ok());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
