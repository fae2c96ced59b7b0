// The subtree tier's recycling of queued copies: a load whose own copy's
// pages were released reads its file into another evicted brick's copy still
// waiting for its release, with the right answers and bytes; the brick that
// lost that copy loads correctly into the one it got in exchange; damaged,
// resized and deleted files are still rejected (and rebuilt by the caller)
// when read into a recycled copy; concurrent loads and evictions never
// recycle a copy that a live accel reads.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/bvh_brick.h"
#include "core/accel/bvh/bvh_brick_serializer.h"
#include "core/cache/subtree_tier.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;

// Bricks of growing size (torus meshes), each a tier file well within one
// copy capacity step, so any of them fits any copy.
constexpr const char* kSpecs[] = {"gen:torus?nu=12&nv=6", "gen:torus?nu=16&nv=8", "gen:torus?nu=24&nv=12",
                                  "gen:torus?nu=32&nv=16"};
constexpr uint32_t kBricks = 4;

class SubtreeTierRecycleTest : public ::testing::Test {
 protected:
  struct Brick {
    std::unique_ptr<BvhBrickAccel> built;
    SubtreeKey key;
    std::vector<Ray> rays;
    std::vector<Hit> want;
  };

  void SetUp() override {
    for (uint32_t i = 0; i < kBricks; ++i) {
      BrickData data = accel_test::load_brick_from(kSpecs[i]);
      data.brick_id = i;
      Brick brick;
      brick.rays = accel_test::rays_from_outside(accel_test::bounds_of(data), 400, 11 + i);
      brick.built = std::move(BvhBrickAccel::build(std::move(data), config_)).value();
      brick.key = {i, 0x5eed0000ull + i, brick.built->triangle_count(), serializer_.structure_key()};
      brick.want = answers(*brick.built, brick.rays);
      bricks_.push_back(std::move(brick));
    }
    open_tier();
  }

  // A new tier on `directory` (by default the test's).
  void open_tier(const std::string& directory = "") {
    auto tier = SubtreeTier::open({directory.empty() ? dir_.path() : directory}, serializer_);
    ASSERT_TRUE(tier.ok()) << tier.status().to_string();
    tier_ = std::move(tier).value();
  }

  static std::vector<Hit> answers(const BrickAccel& accel, const std::vector<Ray>& rays) {
    std::vector<Hit> hits(rays.size());
    accel.intersect(accel_test::all_ids(rays.size()), rays.data(), hits.data());
    return hits;
  }

  // The accel answers as the built brick does, bitwise, from its file's copy.
  ::testing::AssertionResult right(const BrickAccel* accel, uint32_t brick) const {
    if (accel == nullptr) return ::testing::AssertionFailure() << "brick " << brick << " not loaded";
    const Brick& b = bricks_[brick];
    if (accel->memory_bytes() != b.built->memory_bytes()) {
      return ::testing::AssertionFailure() << "brick " << brick << " accounts " << accel->memory_bytes()
                                           << " bytes, built " << b.built->memory_bytes();
    }
    const auto* bvh = dynamic_cast<const BvhBrickAccel*>(accel);
    if (bvh == nullptr || !bvh->in_place()) {
      return ::testing::AssertionFailure() << "brick " << brick << " does not read its file's copy";
    }
    const std::vector<Hit> got = answers(*accel, b.rays);
    if (std::memcmp(got.data(), b.want.data(), got.size() * sizeof(Hit)) != 0) {
      return ::testing::AssertionFailure() << "brick " << brick << " answers differently";
    }
    return ::testing::AssertionSuccess();
  }

  // Stores every brick; returns the loaded accels the tier hands back.
  std::vector<std::unique_ptr<BrickAccel>> store_all() {
    std::vector<std::unique_ptr<BrickAccel>> stored;
    for (uint32_t i = 0; i < kBricks; ++i) {
      stored.push_back(tier_->store(bricks_[i].key, *bricks_[i].built));
      EXPECT_TRUE(right(stored.back().get(), i));
    }
    return stored;
  }

  std::string path(uint32_t brick) const { return tier_->path_of(bricks_[brick].key); }

  // Evicts `loader` (its copy's pages released) then `donor` (its copy
  // queued, pages still mapped), as the cache does with bricks it drops.
  void evict(std::vector<std::unique_ptr<BrickAccel>>& stored, uint32_t loader, uint32_t donor) {
    stored[loader].reset();
    tier_->release_pending_pages();
    stored[donor].reset();
  }

  testing::TempDir dir_;
  BvhBrickConfig config_;
  BvhBrickSerializer serializer_{config_};
  std::vector<Brick> bricks_;
  std::unique_ptr<SubtreeTier> tier_;
};

TEST_F(SubtreeTierRecycleTest, FilesFitOneCopyStepAndGrowInPages) {
  // The scenarios below rely on it: the largest file fits the smallest copy,
  // and a smaller file is a donor for a larger one.
  store_all();
  for (uint32_t i = 0; i + 1 < kBricks; ++i) {
    EXPECT_LT(fs::file_size(path(i)) / 4096, fs::file_size(path(i + 1)) / 4096) << i;
  }
  EXPECT_LE(fs::file_size(path(kBricks - 1)), MappedFile::kCopyCapacityStep);
}

TEST_F(SubtreeTierRecycleTest, ALoadReadsIntoAnotherEvictedBricksQueuedCopy) {
  auto stored = store_all();
  const uint32_t loader = 3, donor = 0;
  evict(stored, loader, donor);

  std::unique_ptr<BrickAccel> loaded = tier_->load(bricks_[loader].key);
  EXPECT_TRUE(right(loaded.get(), loader));
  SubtreeTierCounters c = tier_->counters();
  EXPECT_EQ(c.loads, 1u);
  EXPECT_EQ(c.loads_recycled, 1u) << "read into the donor's populated copy";
  EXPECT_EQ(c.loads_kept, 0u);
  EXPECT_EQ(c.bytes_read, fs::file_size(path(loader)));
  EXPECT_EQ(tier_->page_release_counters().taken, 1u);

  // The donor lost its copy and got the loader's released one: its next load
  // reads its file into that, mapping nothing.
  std::unique_ptr<BrickAccel> again = tier_->load(bricks_[donor].key);
  EXPECT_TRUE(right(again.get(), donor));
  c = tier_->counters();
  EXPECT_EQ(c.loads, 2u);
  EXPECT_EQ(c.loads_kept, 1u);
  EXPECT_EQ(c.loads_recycled, 1u) << "nothing queued to recycle";
  EXPECT_TRUE(right(loaded.get(), loader)) << "still intact";

  // Round after round: bricks 3 and 2 evicted and released, 0 and 1 evicted
  // and queued; 3 and 2 then recycle 1's and 0's copies (the fullest that
  // fits first), and 1 and 0 read into 3's and 2's.
  stored[donor] = std::move(again);
  stored[loader] = std::move(loaded);
  for (int round = 0; round < 3; ++round) {
    stored[3].reset();
    stored[2].reset();
    tier_->release_pending_pages();
    stored[0].reset();
    stored[1].reset();
    for (uint32_t i = kBricks; i-- > 0;) {
      stored[i] = tier_->load(bricks_[i].key);
      EXPECT_TRUE(right(stored[i].get(), i)) << "round " << round;
    }
  }
  c = tier_->counters();
  EXPECT_EQ(c.loads, 2u + 3 * kBricks);
  EXPECT_EQ(c.loads_recycled, 1u + 3 * 2);
  EXPECT_EQ(c.loads_kept, 1u + 3 * 2);
  EXPECT_EQ(c.rejected(), 0u);
  EXPECT_EQ(tier_->page_release_counters().taken, c.loads_recycled);
}

TEST_F(SubtreeTierRecycleTest, ABrickWithNoKeptCopyRecyclesAndTheDonorMakesANewOne) {
  auto stored = store_all();
  // A second tier on the directory keeps no copies yet.
  stored.clear();
  open_tier();
  std::unique_ptr<BrickAccel> donor = tier_->load(bricks_[0].key);
  ASSERT_TRUE(right(donor.get(), 0));
  donor.reset();  // queued
  std::unique_ptr<BrickAccel> loaded = tier_->load(bricks_[2].key);
  EXPECT_TRUE(right(loaded.get(), 2));
  EXPECT_EQ(tier_->counters().loads_recycled, 1u);
  donor = tier_->load(bricks_[0].key);
  EXPECT_TRUE(right(donor.get(), 0)) << "a new copy";
  EXPECT_EQ(tier_->counters().loads_kept, 0u);
  EXPECT_EQ(tier_->counters().loads_recycled, 1u);
  EXPECT_TRUE(right(loaded.get(), 2));
}

// A damaged file read into a recycled copy is rejected as any other load's:
// counted, deleted, nullptr (the caller rebuilds and stores again); the
// donor still loads. Damage after the write: a flipped byte (same size), a
// byte appended (within the copy's capacity), the file grown past it,
// truncated, deleted.
TEST_F(SubtreeTierRecycleTest, DamagedResizedOrDeletedFilesAreRejectedWhenRecycled) {
  enum Damage { kFlipped, kAppended, kGrownPastCapacity, kTruncated, kDeleted };
  for (const Damage damage : {kFlipped, kAppended, kGrownPastCapacity, kTruncated, kDeleted}) {
    SCOPED_TRACE("damage " + std::to_string(damage));
    open_tier(dir_.file("damage" + std::to_string(damage)));
    auto stored = store_all();
    const uint32_t loader = 2, donor = 1;
    evict(stored, loader, donor);
    std::string bytes = testing::read_file_bytes(path(loader));
    switch (damage) {
      case kFlipped: bytes[bytes.size() / 2] ^= 0x10; break;
      case kAppended: bytes += '\0'; break;
      case kGrownPastCapacity: bytes += std::string(MappedFile::kCopyCapacityStep, '\0'); break;
      case kTruncated: bytes.resize(bytes.size() - 5000); break;
      case kDeleted: break;
    }
    if (damage == kDeleted) {
      fs::remove(path(loader));
    } else {
      testing::write_text_file(path(loader), bytes);  // in place, as a careless user would
    }
    EXPECT_EQ(tier_->load(bricks_[loader].key), nullptr);
    const SubtreeTierCounters c = tier_->counters();
    EXPECT_EQ(c.loads, 0u);
    EXPECT_EQ(c.rejected_corrupt, damage == kDeleted ? 0u : 1u);
    EXPECT_EQ(c.absent, damage == kDeleted ? 1u : 0u);
    EXPECT_EQ(tier_->page_release_counters().taken, 1u) << "the load took the donor's copy";
    EXPECT_FALSE(fs::exists(path(loader))) << "the bad file is gone";
    EXPECT_EQ(c.files, kBricks - 1);

    std::unique_ptr<BrickAccel> again = tier_->load(bricks_[donor].key);
    EXPECT_TRUE(right(again.get(), donor));
    EXPECT_EQ(tier_->counters().loads_kept, 1u) << "into the loader's released copy";
    // The rebuild the cache would make is stored and loaded again.
    std::unique_ptr<BrickAccel> rebuilt = tier_->store(bricks_[loader].key, *bricks_[loader].built);
    EXPECT_TRUE(right(rebuilt.get(), loader));
    rebuilt.reset();
    tier_->release_pending_pages();
    EXPECT_TRUE(right(tier_->load(bricks_[loader].key).get(), loader));
    EXPECT_TRUE(right(again.get(), donor));
  }
}

// Threads load, check, hold and drop bricks while others do the same and
// batches are flushed: queued copies are recycled all the time, and an accel
// never has its copy taken from under it (its answers would change, or a
// release would zero its pages).
TEST_F(SubtreeTierRecycleTest, ConcurrentLoadsNeverRecycleACopyALiveAccelReads) {
  auto stored = store_all();
  stored.clear();
  constexpr int kThreads = 4;
  constexpr int kLoadsPerThread = 150;
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(static_cast<unsigned>(t) + 1);
      std::vector<std::pair<uint32_t, std::unique_ptr<BrickAccel>>> held;
      for (int n = 0; n < kLoadsPerThread; ++n) {
        const uint32_t brick = rng() % kBricks;
        std::unique_ptr<BrickAccel> accel = tier_->load(bricks_[brick].key);
        if (!right(accel.get(), brick)) ++failures;
        held.emplace_back(brick, std::move(accel));
        if (held.size() > 2 || rng() % 3 == 0) {
          const std::size_t drop = rng() % held.size();
          if (!right(held[drop].second.get(), held[drop].first)) ++failures;
          held.erase(held.begin() + static_cast<std::ptrdiff_t>(drop));
        }
        if (rng() % 16 == 0) tier_->release_pending_pages();
      }
      for (const auto& [brick, accel] : held) {
        if (!right(accel.get(), brick)) ++failures;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  const SubtreeTierCounters c = tier_->counters();
  EXPECT_EQ(c.loads, static_cast<uint64_t>(kThreads * kLoadsPerThread));
  EXPECT_EQ(c.rejected(), 0u);
  EXPECT_GT(c.loads_recycled, 0u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
