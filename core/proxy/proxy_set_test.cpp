#include "core/proxy/proxy_set.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "core/proxy/proxy_file.h"
#include "core/store/scene_packer.h"
#include "core/store/store_format.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::TempDir;

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return std::move(s).str();
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

std::string pack_into(const TempDir& dir, const std::string& name, const std::vector<std::string>& inputs) {
  PackOptions options;
  options.inputs = inputs;
  options.output = dir.file(name);
  options.brick_triangles = 150;
  options.sync = false;
  const auto summary = pack_scene(options);
  EXPECT_TRUE(summary.ok()) << summary.status().to_string();
  return options.output;
}

std::shared_ptr<const SceneStore> open_store(const std::string& path) {
  auto store = SceneStore::open(path);
  EXPECT_TRUE(store.ok()) << store.status().to_string();
  return std::move(store).value();
}

// Every voxel of every brick's domain is occupied in both sets or in neither.
void expect_same_voxels(const ProxySet& a, const ProxySet& b) {
  ASSERT_EQ(a.brick_count(), b.brick_count());
  EXPECT_EQ(a.active_voxels(), b.active_voxels());
  for (uint32_t id = 0; id < a.brick_count(); ++id) {
    const ProxyFrame& f = a.brick(id).frame();
    ASSERT_EQ(f.dims_IS, b.brick(id).frame().dims_IS);
    ASSERT_EQ(f.origin_WS, b.brick(id).frame().origin_WS);
    for (int32_t i = 0; i < f.dims_IS[0]; ++i)
      for (int32_t j = 0; j < f.dims_IS[1]; ++j)
        for (int32_t k = 0; k < f.dims_IS[2]; ++k)
          ASSERT_EQ(a.brick(id).is_occupied(i, j, k), b.brick(id).is_occupied(i, j, k)) << "brick " << id;
  }
}

class ProxySetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = pack_into(dir_, "scene", {"gen:sphere?level=3", "gen:torus?nu=24&nv=12&cx=2"});
    store_ = open_store(path_);
    proxies_path_ = path_ + "/" + kProxyFileName;
    manifest_bytes_ = read_bytes(path_ + "/" + kManifestFileName);
    bricks_bytes_ = read_bytes(path_ + "/" + kBrickDataFileName);
  }
  void TearDown() override {
    // The store's own files are never touched.
    EXPECT_EQ(read_bytes(path_ + "/" + kManifestFileName), manifest_bytes_);
    EXPECT_EQ(read_bytes(path_ + "/" + kBrickDataFileName), bricks_bytes_);
    // No temporary files are left behind: the store holds its files and proxies.bin at most.
    for (const auto& entry : fs::directory_iterator(path_)) {
      const std::string name = entry.path().filename().string();
      EXPECT_TRUE(name == kManifestFileName || name == kBrickDataFileName || name == kProxyFileName)
          << entry.path();
    }
  }

  std::unique_ptr<const ProxySet> open(ProxyOpenReport& report, uint32_t resolution = 32) {
    ProxyBuildConfig config;
    config.resolution = resolution;
    auto set = ProxySet::open(*store_, config, &report);
    EXPECT_TRUE(set.ok()) << set.status().to_string();
    return std::move(set).value();
  }

  TempDir dir_;
  std::string path_, proxies_path_, manifest_bytes_, bricks_bytes_;
  std::shared_ptr<const SceneStore> store_;
};

TEST_F(ProxySetTest, FirstOpenBuildsAndWritesTheFileAndTheNextLoadsTheSameProxies) {
  ASSERT_FALSE(fs::exists(proxies_path_));
  ProxyOpenReport first;
  const auto built = open(first);
  EXPECT_FALSE(first.loaded);
  EXPECT_TRUE(first.written) << first.write_error;
  EXPECT_TRUE(contains(first.rebuild_reason, "does not exist")) << first.rebuild_reason;
  ASSERT_TRUE(fs::exists(proxies_path_));
  EXPECT_EQ(built->brick_count(), store_->brick_count());
  EXPECT_GT(built->active_voxels(), 0u);
  EXPECT_GT(built->memory_bytes(), built->brick_count() * 1024u);

  ProxyOpenReport second;
  const auto loaded = open(second);
  EXPECT_TRUE(second.loaded) << second.rebuild_reason;
  EXPECT_FALSE(second.written);
  expect_same_voxels(*built, *loaded);
  EXPECT_EQ(built->memory_bytes(), loaded->memory_bytes());

  const auto header = read_proxy_file_header(proxies_path_);
  ASSERT_TRUE(header.ok()) << header.status().to_string();
  EXPECT_EQ(header->resolution, 32u);
  EXPECT_EQ(header->brick_count, store_->brick_count());
  EXPECT_EQ(header->store_fingerprint, store_fingerprint(store_->manifest()));
  EXPECT_EQ(header->active_voxels, built->active_voxels());
}

TEST_F(ProxySetTest, CorruptTruncatedOrGarbageFilesAreDetectedAndRebuilt) {
  ProxyOpenReport report;
  const auto reference = open(report);
  const std::string good = read_bytes(proxies_path_);
  struct Case {
    std::string name, bytes, reason;
  };
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x04;
  std::string header_flipped = good;
  header_flipped[offsetof(ProxyFileHeader, payload_checksum)] ^= 0x01;
  const std::vector<Case> cases = {
      {"payload byte flipped", flipped, "checksum"},
      {"checksum flipped", header_flipped, "checksum"},
      {"truncated", good.substr(0, good.size() - 100), "truncated"},
      {"header only, cut", good.substr(0, 40), "truncated"},
      {"too long", good + "x", "too long"},
      {"garbage", std::string(good.size(), 'x'), "bad magic"},
      {"empty", "", "truncated"},
  };
  for (const Case& c : cases) {
    write_bytes(proxies_path_, c.bytes);
    ProxyOpenReport rebuilt;
    const auto set = open(rebuilt);
    EXPECT_FALSE(rebuilt.loaded) << c.name;
    EXPECT_TRUE(rebuilt.written) << c.name;
    EXPECT_TRUE(contains(rebuilt.rebuild_reason, c.reason)) << c.name << ": " << rebuilt.rebuild_reason;
    expect_same_voxels(*reference, *set);
    EXPECT_EQ(read_bytes(proxies_path_), good) << c.name << ": the rewritten file differs";
    ProxyOpenReport again;
    open(again);
    EXPECT_TRUE(again.loaded) << c.name << ": " << again.rebuild_reason;
  }
}

TEST_F(ProxySetTest, AnotherResolutionOrAnotherStoresFileIsRebuilt) {
  ProxyOpenReport report;
  const auto at32 = open(report);
  const auto at8 = open(report, 8);
  EXPECT_FALSE(report.loaded);
  EXPECT_TRUE(contains(report.rebuild_reason, "resolution 32, wanted 8")) << report.rebuild_reason;
  EXPECT_LT(at8->active_voxels(), at32->active_voxels());
  open(report, 8);
  EXPECT_TRUE(report.loaded);

  // A proxies.bin copied from another store (same brick count is not enough).
  const std::string other =
      pack_into(dir_, "other", {"gen:sphere?level=3&radius=2", "gen:torus?nu=24&nv=12&cx=2"});
  const auto other_store = open_store(other);
  ProxyBuildConfig config;
  ASSERT_TRUE(ProxySet::open(*other_store, config).ok());
  fs::copy_file(other + "/" + kProxyFileName, proxies_path_, fs::copy_options::overwrite_existing);
  open(report);
  EXPECT_FALSE(report.loaded);
  EXPECT_TRUE(contains(report.rebuild_reason, "another scene store")) << report.rebuild_reason;
  open(report);
  EXPECT_TRUE(report.loaded);
}

TEST_F(ProxySetTest, WhenProxiesBinCannotBeReplacedTheProxiesStayInMemory) {
  // A directory in the way: the write is refused (also for root), naming it; nothing is left behind.
  fs::create_directories(proxies_path_ + "/in_the_way");
  ProxyOpenReport report;
  const auto set = open(report);
  EXPECT_FALSE(report.loaded);
  EXPECT_FALSE(report.written);
  EXPECT_TRUE(contains(report.write_error, proxies_path_ + ": it is a directory")) << report.write_error;
  EXPECT_EQ(set->brick_count(), store_->brick_count());
  EXPECT_GT(set->active_voxels(), 0u);
  fs::remove_all(proxies_path_);
}

TEST_F(ProxySetTest, AnUnwritableStoreKeepsTheProxiesInMemory) {
  ASSERT_EQ(::chmod(path_.c_str(), 0555), 0);
  if (::access(path_.c_str(), W_OK) == 0) {
    ::chmod(path_.c_str(), 0755);
    GTEST_SKIP() << "running as root: permissions do not stop writes";
  }
  ProxyOpenReport report;
  const auto set = open(report);
  ::chmod(path_.c_str(), 0755);
  EXPECT_FALSE(report.loaded);
  EXPECT_FALSE(report.written);
  EXPECT_FALSE(report.write_error.empty());
  EXPECT_EQ(set->brick_count(), store_->brick_count());
  EXPECT_FALSE(fs::exists(proxies_path_));
}

TEST_F(ProxySetTest, AnUnreadableBrickGetsNoProxyAndNothingIsWritten) {
  TempDir copy_dir;
  const std::string copy = copy_dir.file("scene");
  fs::copy(path_, copy, fs::copy_options::recursive);
  const uint32_t bad = store_->brick_count() / 2;
  {
    const BrickRecord& record = store_->manifest().bricks[bad];
    std::fstream file(copy + "/" + kBrickDataFileName, std::ios::in | std::ios::out | std::ios::binary);
    const auto at = static_cast<std::streamoff>(record.offset + sizeof(BrickHeader) + 8);
    file.seekp(at);
    file.put('\x7f');
    ASSERT_TRUE(file.good());
  }
  const auto corrupted = open_store(copy);
  ProxyOpenReport report;
  auto set = ProxySet::open(*corrupted, ProxyBuildConfig{}, &report);
  ASSERT_TRUE(set.ok()) << set.status().to_string();
  EXPECT_EQ((*set)->bricks_without_proxy(), 1u);
  EXPECT_FALSE(report.written);
  EXPECT_FALSE(fs::exists(copy + "/" + kProxyFileName));
  Ray anything;
  anything.origin = {100, 100, 100};
  anything.direction = {1, 0, 0};
  EXPECT_TRUE((*set)->brick(bad).may_hit(anything, 0, 1, kMollerTrumboreHitRounding));  // never skipped
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
