#include "core/store/scene_store.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/store/scene_packer.h"
#include "core/store/store_format.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::TempDir;

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A store of a few dozen small bricks, packed fresh for every test.
class SceneStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    PackOptions options;
    options.inputs = {"gen:sphere?level=3", "gen:torus?nu=16&nv=8"};
    options.output = store_;
    options.brick_triangles = 64;
    options.sync = false;
    const auto summary = pack_scene(options);
    ASSERT_TRUE(summary.ok()) << summary.status().to_string();
    ASSERT_GE(summary->bricks, 12u);
    auto store = SceneStore::open(store_);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    manifest_ = (*store)->manifest();
    for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
      BrickData brick;
      ASSERT_TRUE((*store)->load_brick(b, brick).ok());
      originals_.push_back(std::move(brick));
    }
  }

  std::string bricks_path() const { return store_ + "/" + kBrickDataFileName; }
  std::string manifest_path() const { return store_ + "/" + kManifestFileName; }

  // Bricks other than `except` load and equal what was packed.
  void expect_other_bricks_load(const SceneStore& store, uint32_t except) {
    BrickData brick;
    for (uint32_t b = 0; b < store.brick_count(); ++b) {
      if (b == except) continue;
      const Status s = store.load_brick(b, brick);
      ASSERT_TRUE(s.ok()) << "brick " << b << ": " << s.to_string();
      EXPECT_EQ(brick.triangles, originals_[b].triangles) << b;
      EXPECT_EQ(brick.ids, originals_[b].ids) << b;
    }
  }

  TempDir dir_;
  std::string store_ = dir_.file("scene");
  Manifest manifest_;
  std::vector<BrickData> originals_;
};

TEST_F(SceneStoreTest, OpensAndReportsTheManifestAndSize) {
  auto store = SceneStore::open(store_);
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->directory(), store_);
  EXPECT_EQ((*store)->manifest().format_version, kStoreFormatVersion);
  EXPECT_EQ((*store)->manifest().triangle_count, 1280u + 256u);
  EXPECT_EQ((*store)->bytes_on_disk(), fs::file_size(bricks_path()) + fs::file_size(manifest_path()));
}

TEST_F(SceneStoreTest, FlippedByteAnywhereInABrickIsDataLossNamingThatBrickWhileOthersStillLoad) {
  const uint32_t k = static_cast<uint32_t>(manifest_.bricks.size() / 2);
  const BrickRecord& record = manifest_.bricks[k];
  const std::string original = read_bytes(bricks_path());
  const uint64_t n = record.triangle_count;
  const struct {
    const char* where;
    uint64_t offset;
  } places[] = {
      {"header magic", 0},
      {"header brick id", 8},
      {"header triangle count", 12},
      {"first position", sizeof(BrickHeader)},
      {"a middle position", sizeof(BrickHeader) + n * sizeof(Triangle) / 2 + 1},
      {"first id", sizeof(BrickHeader) + n * sizeof(Triangle)},
      {"last byte", record.size_bytes - 1},
  };
  for (const auto& place : places) {
    SCOPED_TRACE(place.where);
    std::string bytes = original;
    bytes[record.offset + place.offset] ^= 0x10;
    write_bytes(bricks_path(), bytes);
    auto store = SceneStore::open(store_);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    BrickData brick;
    const Status s = (*store)->load_brick(k, brick);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << s.to_string();
    EXPECT_TRUE(contains(s.message(), "brick " + std::to_string(k) + " ")) << s.message();
    expect_other_bricks_load(**store, k);
  }
}

TEST_F(SceneStoreTest, TruncatedBrickDataFailsOpenNamingTheFirstCutBrick) {
  const std::string original = read_bytes(bricks_path());
  const uint32_t last = static_cast<uint32_t>(manifest_.bricks.size() - 1);
  const uint32_t middle = last / 2;
  const struct {
    uint32_t brick;
    uint64_t keep;
  } cuts[] = {
      {last, manifest_.bricks[last].offset + manifest_.bricks[last].size_bytes - 1},
      {last, manifest_.bricks[last].offset + 3},
      {middle, manifest_.bricks[middle].offset + 100},
      {0, 0},
  };
  for (const auto& cut : cuts) {
    SCOPED_TRACE("keep " + std::to_string(cut.keep) + " bytes");
    write_bytes(bricks_path(), original.substr(0, cut.keep));
    auto store = SceneStore::open(store_);
    ASSERT_FALSE(store.ok());
    EXPECT_EQ(store.status().code(), StatusCode::kDataLoss);
    EXPECT_TRUE(contains(store.status().message(), "brick " + std::to_string(cut.brick) + " "))
        << store.status().message();
  }
}

TEST_F(SceneStoreTest, MissingBrickDataFileFailsOpen) {
  fs::remove(bricks_path());
  auto store = SceneStore::open(store_);
  ASSERT_FALSE(store.ok());
  EXPECT_TRUE(contains(store.status().message(), kBrickDataFileName)) << store.status().message();
}

TEST_F(SceneStoreTest, FlippedByteAnywhereInTheManifestFailsOpen) {
  const std::string original = read_bytes(manifest_path());
  ASSERT_GT(original.size(), sizeof(StoreFileHeader));
  for (size_t i = 0; i < original.size(); ++i) {
    std::string bytes = original;
    bytes[i] ^= 0x5a;
    write_bytes(manifest_path(), bytes);
    const auto store = SceneStore::open(store_);
    ASSERT_FALSE(store.ok()) << "flipping manifest byte " << i << " went unnoticed";
    const StatusCode code = store.status().code();
    if (i < offsetof(StoreFileHeader, format_version)) {
      EXPECT_TRUE(contains(store.status().message(), "magic")) << i << ": " << store.status().message();
    } else if (i < offsetof(StoreFileHeader, header_bytes)) {
      EXPECT_EQ(code, StatusCode::kFailedPrecondition) << i << ": " << store.status().message();
    } else {
      EXPECT_EQ(code, StatusCode::kDataLoss) << i << ": " << store.status().message();
    }
  }
}

TEST_F(SceneStoreTest, TruncatedOrExtendedManifestIsDataLoss) {
  const std::string original = read_bytes(manifest_path());
  for (const size_t keep : {size_t{0}, size_t{7}, sizeof(StoreFileHeader) - 1, sizeof(StoreFileHeader),
                            original.size() / 2, original.size() - 1}) {
    SCOPED_TRACE("keep " + std::to_string(keep));
    write_bytes(manifest_path(), original.substr(0, keep));
    const auto store = SceneStore::open(store_);
    ASSERT_FALSE(store.ok());
    EXPECT_EQ(store.status().code(), StatusCode::kDataLoss) << store.status().message();
  }
  write_bytes(manifest_path(), original + "x");
  const auto store = SceneStore::open(store_);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss) << store.status().message();
}

TEST_F(SceneStoreTest, OtherFormatVersionIsFailedPreconditionNamingBothVersions) {
  std::string bytes = read_bytes(manifest_path());
  const uint32_t version = 1;  // the format before the brick bounds
  static_assert(kStoreFormatVersion != 1);
  std::memcpy(bytes.data() + offsetof(StoreFileHeader, format_version), &version, sizeof version);
  write_bytes(manifest_path(), bytes);
  const auto store = SceneStore::open(store_);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_TRUE(contains(store.status().message(), "format version 1")) << store.status().message();
  EXPECT_TRUE(contains(store.status().message(), "outcore pack --force")) << store.status().message();
  EXPECT_TRUE(contains(store.status().message(), "format version " + std::to_string(kStoreFormatVersion)))
      << store.status().message();
}

TEST_F(SceneStoreTest, DirectoryWithoutManifestIsNotFound) {
  fs::remove(manifest_path());
  const auto store = SceneStore::open(store_);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(contains(store.status().message(), kManifestFileName)) << store.status().message();
}

TEST(SceneStore, MissingDirectoryAndEmptyDirectoryAreNotFound) {
  TempDir dir;
  for (const std::string& path : {dir.file("nothing-here"), dir.path()}) {
    const auto store = SceneStore::open(path);
    ASSERT_FALSE(store.ok()) << path;
    EXPECT_EQ(store.status().code(), StatusCode::kNotFound) << path;
    EXPECT_TRUE(contains(store.status().message(), path)) << store.status().message();
  }
}

TEST_F(SceneStoreTest, BrickIdBeyondTheSceneIsOutOfRange) {
  auto store = SceneStore::open(store_);
  ASSERT_TRUE(store.ok());
  BrickData brick;
  const Status s = (*store)->load_brick((*store)->brick_count(), brick);
  EXPECT_EQ(s.code(), StatusCode::kOutOfRange);
  EXPECT_TRUE(contains(s.message(), "brick " + std::to_string((*store)->brick_count()))) << s.message();
}

// A manifest that is well-formed and correctly checksummed but inconsistent is
// still refused.
TEST_F(SceneStoreTest, InconsistentManifestIsDataLoss) {
  const auto rewrite_and_open = [&](const Manifest& m) {
    EXPECT_TRUE(write_manifest(manifest_path(), m).ok());
    return SceneStore::open(store_);
  };
  {
    Manifest m = manifest_;
    m.triangle_count += 1;
    EXPECT_EQ(rewrite_and_open(m).status().code(), StatusCode::kDataLoss);
  }
  {
    Manifest m = manifest_;
    m.bricks[1].offset += 8;  // misaligned
    EXPECT_EQ(rewrite_and_open(m).status().code(), StatusCode::kDataLoss);
  }
  {
    Manifest m = manifest_;
    for (UpperNode& node : m.upper.nodes) {
      if (node.is_leaf && node.child_or_brick == 1) node.child_or_brick = 0;  // brick 0 twice, 1 never
    }
    EXPECT_EQ(rewrite_and_open(m).status().code(), StatusCode::kDataLoss);
  }
  {
    Manifest m = manifest_;
    m.upper.nodes.pop_back();
    EXPECT_EQ(rewrite_and_open(m).status().code(), StatusCode::kDataLoss);
  }
  {
    Manifest m = manifest_;
    m.upper.nodes[0].bounds.hi.x = m.upper.nodes[0].bounds.lo.x;  // root no longer contains its children
    EXPECT_EQ(rewrite_and_open(m).status().code(), StatusCode::kDataLoss);
  }
  EXPECT_TRUE(rewrite_and_open(manifest_).ok()) << "the untouched manifest must open again";
}

TEST_F(SceneStoreTest, ConcurrentLoadsFromManyThreadsReturnTheSameBricks) {
  auto store = SceneStore::open(store_);
  ASSERT_TRUE(store.ok());
  const SceneStore& shared = **store;
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      BrickData brick;
      for (int round = 0; round < 20; ++round) {
        for (uint32_t i = 0; i < shared.brick_count(); ++i) {
          const uint32_t b =
              (i * 7 + static_cast<uint32_t>(t) * 3 + static_cast<uint32_t>(round)) % shared.brick_count();
          if (!shared.load_brick(b, brick).ok() || brick.triangles != originals_[b].triangles ||
              brick.ids != originals_[b].ids) {
            ++mismatches[t];
          }
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(mismatches, std::vector<int>(4, 0));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
