// The subtree tier with the brick cache: bricks built once are loaded instead
// of rebuilt (in this cache after evictions, and in a later cache on the same
// directory), accounted with exactly the built bytes; answers under a tiny
// budget with the tier equal unlimited-budget answers bitwise (every bvh
// triangle test, a model and generator scenes); corrupt, truncated, other
// version, wrong checksum and wrong options files are counted by reason and
// rebuilt; bricks read their file's copy in place; a file's structure is
// checked once, then trusted until replaced; files damaged under a running
// engine cost a rebuild; concurrent misses of different bricks; a
// bounded directory; an unwritable one; embree refused; access traces record
// loads and replay consistently.
#include "core/cache/subtree_tier.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/accel/bvh/bvh_brick.h"
#include "core/cache/brick_cache.h"
#include "core/cache/cache_simulator.h"
#include "core/cache/eviction_policy.h"
#include "core/query/query_engine.h"
#include "core/store/scene_store.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;

constexpr uint64_t kUnlimited = uint64_t{1} << 40;

std::unique_ptr<BrickBuilder> bvh_builder(const BrickAccelOptions& options = {}) {
  auto builder = make_brick_builder("bvh", options);
  EXPECT_TRUE(builder.ok()) << builder.status().to_string();
  return builder.ok() ? std::move(builder).value() : nullptr;
}

std::unique_ptr<EvictionPolicy> lru() {
  auto policy = make_eviction_policy("lru");
  EXPECT_TRUE(policy.ok());
  return std::move(policy).value();
}

std::size_t files_in(const std::string& dir) {
  std::size_t n = 0;
  for (const auto& entry : fs::directory_iterator(dir)) n += entry.path().extension() == ".subtree";
  return n;
}

std::size_t temp_files_in(const std::string& dir) {
  std::size_t n = 0;
  for (const auto& entry : fs::directory_iterator(dir)) n += entry.path().filename().string()[0] == '.';
  return n;
}

bool bitwise_equal(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
}

// One store (gen:sphere level 5, bricks of <= 512 triangles), packed once.
class SubtreeTierTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = testing::pack_test_scene({"gen:sphere?level=5"}, 512).release();
    auto store = SceneStore::open(scene_->path);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    store_ = new std::shared_ptr<const SceneStore>(std::move(store).value());
  }
  static void TearDownTestSuite() {
    delete store_;
    delete scene_;
    store_ = nullptr;
    scene_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(store_, nullptr);
    ASSERT_GE(bricks(), 16u);
  }

  static uint32_t bricks() { return (*store_)->brick_count(); }

  // A bvh cache with a tier in `tier_dir` (none when empty).
  static std::unique_ptr<BrickCache> make_cache(uint64_t budget, const std::string& tier_dir,
                                                uint64_t tier_bytes = 0,
                                                const BrickAccelOptions& options = {}) {
    auto cache = std::make_unique<BrickCache>(*store_, bvh_builder(options), lru(), budget);
    if (!tier_dir.empty()) {
      const Status enabled = cache->enable_subtree_tier({tier_dir, tier_bytes});
      EXPECT_TRUE(enabled.ok()) << enabled.to_string();
    }
    return cache;
  }

  // Acquires every brick once; returns each one's memory_bytes().
  static std::vector<uint64_t> acquire_all(BrickCache& cache) {
    std::vector<uint64_t> bytes;
    for (uint32_t b = 0; b < bricks(); ++b) {
      auto pin = cache.acquire(b);
      EXPECT_TRUE(pin.ok()) << pin.status().to_string();
      bytes.push_back(pin.ok() ? pin->accel().memory_bytes() : 0);
    }
    return bytes;
  }

  static uint64_t max_reservation(const BrickCache& cache) {
    uint64_t most = 0;
    for (const BrickRecord& b : (*store_)->manifest().bricks)
      most = std::max(most, cache.builder().reserve_bytes(b.triangle_count));
    return most;
  }

  static SubtreeKey key_of(const BrickCache& cache, uint32_t brick) {
    const BrickRecord& record = (*store_)->manifest().bricks[brick];
    return {brick, record.checksum, record.triangle_count, cache.builder().serializer()->structure_key()};
  }

  static testing::PackedScene* scene_;
  static std::shared_ptr<const SceneStore>* store_;
};

testing::PackedScene* SubtreeTierTest::scene_ = nullptr;
std::shared_ptr<const SceneStore>* SubtreeTierTest::store_ = nullptr;

TEST_F(SubtreeTierTest, BuiltBricksAreSavedAndALaterCacheLoadsThemWithTheSameBytes) {
  testing::TempDir tier;
  auto first = make_cache(kUnlimited, tier.path());
  const std::vector<uint64_t> built = acquire_all(*first);
  CacheCounters c = first->counters();
  EXPECT_EQ(c.builds, bricks());
  EXPECT_EQ(c.subtree.absent, bricks());
  EXPECT_EQ(c.subtree.loads, 0u);
  EXPECT_EQ(c.subtree.writes, bricks());
  EXPECT_EQ(c.subtree.files, bricks());
  EXPECT_EQ(files_in(tier.path()), bricks());
  EXPECT_EQ(temp_files_in(tier.path()), 0u);
  EXPECT_GT(c.subtree.bytes_written, c.bytes_built / 2);
  const uint64_t resident = c.resident_bytes;

  auto second = make_cache(kUnlimited, tier.path());
  EXPECT_EQ(second->counters().subtree.files, bricks()) << "files found at open";
  const std::vector<uint64_t> loaded = acquire_all(*second);
  c = second->counters();
  EXPECT_EQ(loaded, built) << "a loaded brick accounts exactly the built bytes";
  EXPECT_EQ(c.resident_bytes, resident);
  EXPECT_EQ(c.builds, 0u);
  EXPECT_EQ(c.bytes_built, 0u);
  EXPECT_EQ(c.misses, bricks());
  EXPECT_EQ(c.subtree.loads, bricks());
  EXPECT_EQ(c.subtree.writes, 0u) << "loaded bricks are not written again";
  EXPECT_EQ(c.subtree.rejected(), 0u);
  EXPECT_EQ(c.subtree.bytes_read, first->counters().subtree.bytes_written);
  EXPECT_GT(c.subtree.load_seconds, 0.0);
}

TEST_F(SubtreeTierTest, EvictedBricksAreLoadedBackUnderATinyBudget) {
  testing::TempDir tier;
  auto cache = make_cache(kUnlimited, "");
  const uint64_t budget = 2 * max_reservation(*cache);
  cache = make_cache(budget, tier.path());
  for (int round = 0; round < 3; ++round) acquire_all(*cache);
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.builds, bricks()) << "each brick built once, then loaded";
  EXPECT_EQ(c.subtree.loads, 2u * bricks());
  EXPECT_EQ(c.misses, c.builds + c.subtree.loads);
  EXPECT_GT(c.evictions, 0u);
  EXPECT_LE(c.peak_resident_bytes, budget);
  EXPECT_EQ(c.reservation_overruns, 0u);
}

TEST_F(SubtreeTierTest, BuiltAndLoadedBricksReadTheirFileInPlace) {
  testing::TempDir tier;
  auto cache = make_cache(kUnlimited, tier.path());
  for (int round = 0; round < 2; ++round) {  // built and saved, then loaded by a second cache
    for (uint32_t b = 0; b < bricks(); ++b) {
      auto pin = cache->acquire(b);
      ASSERT_TRUE(pin.ok()) << pin.status().to_string();
      const auto* bvh = dynamic_cast<const BvhBrickAccel*>(&pin->accel());
      ASSERT_NE(bvh, nullptr);
      EXPECT_TRUE(bvh->in_place()) << "brick " << b << " round " << round
                                   << ": the cache keeps the file's copy, not a heap build";
    }
    cache = make_cache(kUnlimited, tier.path());
  }
  // Without a tier a build stays on the heap.
  auto plain = make_cache(kUnlimited, "");
  auto pin = plain->acquire(0);
  ASSERT_TRUE(pin.ok());
  EXPECT_FALSE(dynamic_cast<const BvhBrickAccel&>(pin->accel()).in_place());
}

TEST_F(SubtreeTierTest, FilesAreCheckedInFullOnceThenTrustedUntilReplaced) {
  testing::TempDir tier;
  auto probe = make_cache(kUnlimited, "");
  const uint64_t budget = 2 * max_reservation(*probe);
  {
    // Files this tier wrote are known good: its reloads skip the full check.
    auto writer = make_cache(budget, tier.path());
    for (int round = 0; round < 2; ++round) acquire_all(*writer);
    const SubtreeTierCounters c = writer->counters().subtree;
    EXPECT_EQ(c.writes, bricks());
    EXPECT_EQ(c.loads, bricks());
    EXPECT_EQ(c.loads_checked, 0u);
    EXPECT_EQ(c.loads_kept + c.loads_recycled, bricks())
        << "the written files' copies are kept: reloads read into their own or another evicted brick's";
    // Every evicted brick's pages went through the release queue.
    writer->release_evicted_pages();
    const PageReleaseCounters released = writer->subtree_tier()->page_release_counters();
    EXPECT_GT(writer->counters().evictions, 0u);
    EXPECT_EQ(released.mappings_released + released.cancelled + released.taken, writer->counters().evictions);
  }
  auto reader = make_cache(budget, tier.path());
  // Loads that made a new copy: a load reads into its brick's kept copy, or
  // recycles another evicted brick's queued one (that brick then gets the
  // loader's copy, or none when the loader had none), so only a brick that
  // has no copy makes one, which it then keeps: at most one per brick.
  const auto new_copies = [&] {
    const SubtreeTierCounters t = reader->counters().subtree;
    return t.loads - t.loads_kept - t.loads_recycled;
  };
  acquire_all(*reader);
  EXPECT_EQ(reader->counters().subtree.loads_checked, bricks()) << "found at open: checked on first load";
  acquire_all(*reader);
  EXPECT_EQ(reader->counters().subtree.loads, 2u * bricks());
  EXPECT_EQ(reader->counters().subtree.loads_checked, bricks()) << "unchanged since: trusted";
  EXPECT_GT(reader->counters().subtree.loads_recycled, 0u) << "evicted bricks' queued copies were recycled";
  EXPECT_LE(new_copies(), bricks());

  // Another process replaces two files (a new inode each): one with the same
  // bytes, checked again and used; one corrupt, caught by the checksum. (Their
  // kept copies' pages are released first: a copy still queued for release
  // is this process's own checked bytes and would be used without a read.)
  reader->release_evicted_pages();
  const std::string same = reader->subtree_tier()->path_of(key_of(*reader, 1));
  const std::string bad = reader->subtree_tier()->path_of(key_of(*reader, 2));
  const std::string same_bytes = testing::read_file_bytes(same);
  std::string bad_bytes = testing::read_file_bytes(bad);
  bad_bytes[bad_bytes.size() - 100] ^= 0x01;
  for (const auto& [path, bytes] : {std::pair{same, same_bytes}, std::pair{bad, bad_bytes}}) {
    testing::write_text_file(path + ".new", bytes);
    fs::rename(path + ".new", path);
  }
  acquire_all(*reader);
  const CacheCounters c = reader->counters();
  EXPECT_EQ(c.subtree.loads_checked, bricks() + 1);
  EXPECT_EQ(c.subtree.rejected_corrupt, 1u);
  EXPECT_EQ(c.builds, 1u) << "the corrupt file's brick is rebuilt";
  EXPECT_EQ(c.subtree.loads, 3u * bricks() - 1);
  EXPECT_LE(new_copies(), bricks()) << "a replaced file is read into a kept or recycled copy too";
}

TEST_F(SubtreeTierTest, BadFilesFallBackToARebuildWithTheRightCounter) {
  testing::TempDir tier;
  auto cache = make_cache(kUnlimited, tier.path());
  const std::vector<uint64_t> built = acquire_all(*cache);
  const auto read = testing::read_file_bytes;
  const auto write = testing::write_text_file;
  const SubtreeTier& t = *cache->subtree_tier();
  // 0: a flipped byte; 1: truncated; 2: another format version; 3: the file of
  // another brick (wrong source checksum and id); 4: built with other options.
  std::string bytes = read(t.path_of(key_of(*cache, 0)));
  bytes[bytes.size() / 2] ^= 0x10;
  write(t.path_of(key_of(*cache, 0)), bytes);
  bytes = read(t.path_of(key_of(*cache, 1)));
  write(t.path_of(key_of(*cache, 1)), bytes.substr(0, bytes.size() / 3));
  bytes = read(t.path_of(key_of(*cache, 2)));
  const uint32_t version = kSubtreeFormatVersion + 7;
  std::memcpy(bytes.data() + 8, &version, sizeof(version));
  write(t.path_of(key_of(*cache, 2)), bytes);
  write(t.path_of(key_of(*cache, 3)), read(t.path_of(key_of(*cache, 5))));
  {
    testing::TempDir other;
    auto mt = make_cache(kUnlimited, other.path(), 0, {{"triangle_test", "mt"}});
    ASSERT_TRUE(mt->acquire(4).ok());
    write(t.path_of(key_of(*cache, 4)), read(mt->subtree_tier()->path_of(key_of(*mt, 4))));
  }

  auto fresh = make_cache(kUnlimited, tier.path());
  const std::vector<uint64_t> again = acquire_all(*fresh);
  EXPECT_EQ(again, built);
  CacheCounters c = fresh->counters();
  EXPECT_EQ(c.subtree.rejected_corrupt, 2u);
  EXPECT_EQ(c.subtree.rejected_version, 1u);
  EXPECT_EQ(c.subtree.rejected_stale, 2u);
  EXPECT_EQ(c.builds, 5u);
  EXPECT_EQ(c.subtree.loads, bricks() - 5);
  EXPECT_EQ(c.subtree.writes, 5u) << "the rebuilt bricks replace the bad files";

  // The rewritten files are good: a third cache loads every brick.
  auto third = make_cache(kUnlimited, tier.path());
  acquire_all(*third);
  c = third->counters();
  EXPECT_EQ(c.subtree.loads, bricks());
  EXPECT_EQ(c.subtree.rejected(), 0u);
  EXPECT_EQ(c.builds, 0u);
}

TEST_F(SubtreeTierTest, ConcurrentMissesOfDifferentBricksStayExact) {
  testing::TempDir tier;
  auto probe = make_cache(kUnlimited, "");
  const std::vector<uint64_t> built = acquire_all(*probe);
  // Half the bricks on disk already.
  {
    auto half = make_cache(kUnlimited, tier.path());
    for (uint32_t b = 0; b < bricks(); b += 2) ASSERT_TRUE(half->acquire(b).ok());
  }
  const uint64_t budget = 4 * max_reservation(*probe);
  auto cache = make_cache(budget, tier.path());
  std::atomic<int> wrong_bytes{0}, failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(t);
      for (int i = 0; i < 150; ++i) {
        const uint32_t b = rng() % bricks();
        auto pin = cache->acquire(b);
        if (!pin.ok()) {
          ++failures;
          continue;
        }
        if (pin->accel().memory_bytes() != built[b]) ++wrong_bytes;
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_EQ(wrong_bytes.load(), 0);
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.hits + c.misses, 600u);
  EXPECT_GE(c.misses, c.builds + c.subtree.loads);
  EXPECT_LE(c.builds, bricks()) << "each brick built at most once, later misses load it";
  EXPECT_GT(c.subtree.loads, 0u);
  EXPECT_EQ(c.subtree.rejected(), 0u);
  EXPECT_LE(c.peak_resident_bytes, budget);
  EXPECT_EQ(temp_files_in(tier.path()), 0u);
  uint64_t resident = 0;
  for (const uint32_t b : cache->resident_bricks()) resident += built[b];
  EXPECT_EQ(c.resident_bytes, resident) << "accounting exact after concurrent loads and builds";
}

TEST_F(SubtreeTierTest, BoundedDirectoryKeepsTheMostRecentFilesWithinTheBound) {
  testing::TempDir probe_dir;
  auto probe = make_cache(kUnlimited, probe_dir.path());
  acquire_all(*probe);
  const uint64_t largest_file = [&] {
    uint64_t most = 0;
    for (const auto& entry : fs::directory_iterator(probe_dir.path()))
      most = std::max(most, entry.file_size());
    return most;
  }();
  testing::TempDir tier;
  const uint64_t bound = 5 * largest_file;
  auto cache = make_cache(kUnlimited, tier.path(), bound);
  acquire_all(*cache);
  CacheCounters c = cache->counters();
  EXPECT_EQ(c.subtree.writes, bricks());
  EXPECT_LE(c.subtree.bytes, bound);
  EXPECT_GE(c.subtree.files, 5u);
  EXPECT_EQ(c.subtree.files_evicted, c.subtree.writes - c.subtree.files);
  EXPECT_EQ(files_in(tier.path()), c.subtree.files);
  // The newest brick survived; the first ones were deleted.
  EXPECT_TRUE(fs::exists(cache->subtree_tier()->path_of(key_of(*cache, bricks() - 1))));
  EXPECT_FALSE(fs::exists(cache->subtree_tier()->path_of(key_of(*cache, 0))));

  // Opening with a smaller bound trims the directory.
  auto smaller = make_cache(kUnlimited, tier.path(), 2 * largest_file);
  EXPECT_LE(smaller->counters().subtree.bytes, 2 * largest_file);
  EXPECT_EQ(files_in(tier.path()), smaller->counters().subtree.files);

  // A bound smaller than any file keeps nothing.
  testing::TempDir none;
  auto tiny = make_cache(kUnlimited, none.path(), 1);
  acquire_all(*tiny);
  c = tiny->counters();
  EXPECT_EQ(c.subtree.writes, 0u);
  EXPECT_EQ(c.subtree.writes_too_large, bricks());
  EXPECT_EQ(files_in(none.path()), 0u);
  EXPECT_EQ(temp_files_in(none.path()), 0u);
}

TEST_F(SubtreeTierTest, UnwritableDirectoryCountsFailuresAndStillAnswers) {
  testing::TempDir parent;
  const std::string tier = parent.file("tier");
  auto cache = make_cache(kUnlimited, tier);
  // The directory goes away under the tier (a plain file in its place, which
  // even root cannot create files in).
  fs::remove_all(tier);
  testing::write_text_file(tier, "in the way");
  acquire_all(*cache);
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.builds, bricks());
  EXPECT_EQ(c.subtree.write_failures, bricks());
  EXPECT_EQ(c.subtree.writes, 0u);
}

TEST_F(SubtreeTierTest, StructuresThatCannotBeSerialisedAreRefused) {
  for (const char* name : {"embree", "reference"}) {
    auto builder = make_brick_builder(name, {});
    ASSERT_TRUE(builder.ok());
    BrickCache cache(*store_, std::move(builder).value(), lru(), kUnlimited);
    testing::TempDir tier;
    const Status status = cache.enable_subtree_tier({tier.path(), 0});
    EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition) << name;
    EXPECT_NE(status.message().find(name), std::string::npos) << status.message();
    EXPECT_EQ(cache.subtree_tier(), nullptr);
  }
  auto cache = make_cache(kUnlimited, "");
  testing::TempDir parent;
  testing::write_text_file(parent.file("plain"), "not a directory");
  EXPECT_FALSE(cache->enable_subtree_tier({parent.file("plain"), 0}).ok());
}

TEST_F(SubtreeTierTest, AccessTraceRecordsLoadsAndTheReplayMissesWhereTheLiveCacheDid) {
  testing::TempDir tier, out;
  auto probe = make_cache(kUnlimited, "");
  const uint64_t budget = 3 * max_reservation(*probe);
  {
    auto warm = make_cache(kUnlimited, tier.path());
    for (uint32_t b = 0; b < bricks(); b += 3) ASSERT_TRUE(warm->acquire(b).ok());
  }
  auto writer = AccessTraceWriter::create(out.file("trace.csv"), "test");
  ASSERT_TRUE(writer.ok());
  CacheCounters live;
  {
    auto cache = make_cache(budget, tier.path());
    cache->set_access_trace(*writer);
    for (int round = 0; round < 2; ++round) acquire_all(*cache);
    live = cache->counters();
  }
  ASSERT_TRUE((*writer)->close().ok());
  auto trace = read_access_trace(out.file("trace.csv"));
  ASSERT_TRUE(trace.ok()) << trace.status().to_string();
  uint64_t miss_records = 0, load_records = 0, loaded_bytes = 0;
  double recorded_seconds = 0;
  for (const AccessRecord& r : trace->records) {
    miss_records += r.outcome == AccessOutcome::kMiss;
    load_records += r.outcome == AccessOutcome::kLoad;
    if (r.outcome == AccessOutcome::kLoad) loaded_bytes += r.bytes;
    if (r.outcome == AccessOutcome::kMiss || r.outcome == AccessOutcome::kLoad)
      recorded_seconds += r.build_seconds;
  }
  EXPECT_EQ(miss_records, live.builds);
  EXPECT_EQ(load_records, live.subtree.loads);
  EXPECT_GT(load_records, 0u);
  const TraceProfile profile = TraceProfile::of(*trace);
  auto replay = simulate_policy(*trace, profile, "lru", budget);
  ASSERT_TRUE(replay.ok()) << replay.status().to_string();
  EXPECT_EQ(replay->misses, live.builds + live.subtree.loads);
  EXPECT_EQ(replay->hits, live.hits);
  EXPECT_EQ(replay->evictions, live.evictions);
  EXPECT_EQ(replay->bytes_built, live.bytes_built + loaded_bytes);
  // Each live miss or load is charged its own recorded seconds (a build's
  // include the tier lookup that found nothing, so they are not exactly the
  // tier's load_seconds plus the cache's build_seconds).
  EXPECT_NEAR(replay->build_seconds, recorded_seconds, 1e-9 * recorded_seconds);
}

// ---- through the engine ---------------------------------------------------------

// The answers under an unlimited budget without a tier, and the largest
// reservation of any brick (budgets are multiples of it).
struct UnlimitedRun {
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
  uint64_t largest_reservation = 0;
};

UnlimitedRun run_unlimited(const std::string& store, const EngineOptions& options,
                           const std::vector<Ray>& rays) {
  UnlimitedRun run;
  auto engine = QueryEngine::open(store, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  if (!engine.ok()) return run;
  run.hits.resize(rays.size());
  run.occluded.resize(rays.size());
  EXPECT_TRUE((*engine)->intersect(rays, run.hits, {}).ok());
  EXPECT_TRUE((*engine)->occluded(rays, run.occluded, {}).ok());
  for (const BrickRecord& b : (*engine)->store().manifest().bricks)
    run.largest_reservation =
        std::max(run.largest_reservation, (*engine)->cache().builder().reserve_bytes(b.triangle_count));
  return run;
}

// Every structure with a serialiser, with every triangle test for the bvh
// and one or two for the split-plane trees and the grid (their serialisers
// write the test as a byte, as the bvh's does).
constexpr std::pair<const char*, const char*> kTierStructuresAndTests[] = {{"bvh", "mt"},
                                                                           {"bvh", "watertight"},
                                                                           {"bvh", "double"},
                                                                           {"kdtree", "watertight"},
                                                                           {"kdtree", "mt"},
                                                                           {"bsp", "watertight"},
                                                                           {"grid", "watertight"},
                                                                           {"grid", "double"},
                                                                           {"octree", "watertight"},
                                                                           {"quadtree", "watertight"},
                                                                           {"hgrid", "watertight"}};

TEST(SubtreeTierEngine, TinyBudgetWithTheTierAnswersLikeAnUnlimitedBudget) {
  const auto scene = testing::pack_test_scene(
      {testing::model_path("stanford-bunny.obj"), "gen:torus?nu=48&nv=24&cx=0.3", "gen:sphere?level=4"},
      2048);
  const auto rays = testing::make_test_rays(scene->bounds, 3000, 77);
  for (const auto& [structure, test] : kTierStructuresAndTests) {
    SCOPED_TRACE(structure);
    EngineOptions options;
    options.brick_accel = structure;
    options.accel_options = {{"triangle_test", test}};
    const UnlimitedRun unlimited = run_unlimited(scene->path, options, rays);
    ASSERT_FALSE(unlimited.hits.empty());
    const std::vector<Hit>& want = unlimited.hits;
    const std::vector<uint8_t>& want_occluded = unlimited.occluded;
    const uint64_t most = unlimited.largest_reservation;

    testing::TempDir tier;
    // Two reservations hold several bvh bricks; a split-plane tree's
    // reservation covers its build's events (~10x the built tree), so one,
    // the smallest budget the engine accepts, is what makes it evict.
    options.cache_bytes = (std::string(structure) == "bvh" ? 2 : 1) * most;
    options.subtree_dir = tier.path();
    for (int process = 0; process < 2; ++process) {  // a cold directory, then a warm one
      auto engine = QueryEngine::open(scene->path, options);
      ASSERT_TRUE(engine.ok()) << engine.status().to_string();
      std::vector<Hit> hits(rays.size());
      std::vector<uint8_t> occluded(rays.size());
      QueryStats stats, any_stats;
      ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
      ASSERT_TRUE((*engine)->occluded(rays, occluded, {}, &any_stats).ok());
      EXPECT_TRUE(bitwise_equal(hits, want)) << test << " run " << process;
      EXPECT_EQ(occluded, want_occluded) << test << " run " << process;
      EXPECT_GT(stats.evictions, 0u);
      EXPECT_GT(any_stats.subtree_loads, 0u) << test << ": evicted bricks come back from the tier";
      EXPECT_EQ(stats.subtree_rejects, 0u);
      if (process == 0) {
        EXPECT_GT(stats.subtree_writes, 0u);
        EXPECT_GT(stats.subtree_bytes_written, 0u);
      } else {
        EXPECT_EQ(stats.brick_builds + any_stats.brick_builds, 0u)
            << test << ": a warm directory builds nothing";
        EXPECT_GT(stats.subtree_bytes_read, 0u);
        EXPECT_GT(stats.seconds_subtree_loads, 0.0);
      }
      EXPECT_LE(stats.peak_bytes_resident, options.cache_bytes);
    }
  }
}

// Issue 21, finding 4: another process truncates one tier file and
// overwrites another in place with garbage of the same size while both
// bricks are resident and the engine keeps serving. Rays must still get the
// right answers (the resident bricks read this process's own copy, not the
// file: before, a truncation was a SIGBUS and garbage a SIGSEGV or wrong
// hits), and the damaged files must cost a rebuild each when their bricks
// are loaded again, in this engine (evictions under a small budget) or the
// next one on the directory.
TEST(SubtreeTierEngine, FilesDamagedUnderARunningEngineCostARebuildNotTheProcess) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=5", "gen:torus?nu=64&nv=32&cx=1.2"}, 600);
  const auto rays = testing::make_test_rays(scene->bounds, 3000, 21);
  EngineOptions options;
  options.brick_accel = "bvh";
  const UnlimitedRun unlimited = run_unlimited(scene->path, options, rays);
  ASSERT_FALSE(unlimited.hits.empty());

  testing::TempDir tier;
  options.cache_bytes = 4 * unlimited.largest_reservation;
  options.subtree_dir = tier.path();
  auto engine = QueryEngine::open(scene->path, options);
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  std::vector<Hit> hits(rays.size());
  QueryStats stats;
  ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
  ASSERT_TRUE(bitwise_equal(hits, unlimited.hits));
  ASSERT_GT(stats.evictions, 0u);

  const BrickCache& cache = (*engine)->cache();
  const std::vector<uint32_t> resident = cache.resident_bricks();
  ASSERT_GE(resident.size(), 2u);
  const auto path_of = [&](uint32_t brick) {
    const BrickRecord& record = (*engine)->store().manifest().bricks[brick];
    return cache.subtree_tier()->path_of(
        {brick, record.checksum, record.triangle_count, cache.builder().serializer()->structure_key()});
  };
  const std::string truncated = path_of(resident[0]);
  const std::string overwritten = path_of(resident[1]);
  fs::resize_file(truncated, fs::file_size(truncated) / 3);
  {
    std::string garbage(fs::file_size(overwritten), '\0');
    std::mt19937 random(7);
    for (char& c : garbage) c = static_cast<char>(random());
    std::fstream file(overwritten, std::ios::in | std::ios::out | std::ios::binary);  // in place
    file.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
    ASSERT_TRUE(file.good());
  }

  uint64_t rejects = 0, builds = 0;
  for (int run = 0; run < 3; ++run) {  // the damaged bricks resident, then evicted and loaded again
    std::fill(hits.begin(), hits.end(), Hit{});
    ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
    EXPECT_TRUE(bitwise_equal(hits, unlimited.hits)) << "run " << run;
    EXPECT_GT(stats.subtree_loads, 0u);
    rejects += stats.subtree_rejects;
    builds += stats.brick_builds;
  }
  EXPECT_EQ(builds, rejects) << "every other brick still loads from the tier";
  engine->reset();

  // The next engine on the directory finds every file good or rebuilds it:
  // exactly the two damaged bricks were rebuilt, once each, in all.
  engine = QueryEngine::open(scene->path, options);
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  ASSERT_TRUE((*engine)->intersect(rays, hits, {}, &stats).ok());
  EXPECT_TRUE(bitwise_equal(hits, unlimited.hits));
  rejects += stats.subtree_rejects;
  builds += stats.brick_builds;
  EXPECT_EQ(rejects, 2u);
  EXPECT_EQ(builds, 2u);
  EXPECT_EQ(files_in(tier.path()), static_cast<std::size_t>((*engine)->store().brick_count()));
}

TEST(SubtreeTierEngine, ConcurrentBatchesWithTheTierAnswerLikeOneUnlimitedBatch) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=5", "gen:torus?nu=64&nv=32&cx=1.2"}, 600);
  const auto rays = testing::make_test_rays(scene->bounds, 2000, 5);
  EngineOptions options;
  options.brick_accel = "bvh";
  const UnlimitedRun unlimited = run_unlimited(scene->path, options, rays);
  ASSERT_FALSE(unlimited.hits.empty());
  const std::vector<Hit>& want = unlimited.hits;
  const uint64_t most = unlimited.largest_reservation;
  testing::TempDir tier;
  options.cache_bytes = 3 * most;
  options.subtree_dir = tier.path();
  auto engine = QueryEngine::open(scene->path, options);
  ASSERT_TRUE(engine.ok());
  std::atomic<int> wrong{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&] {
      for (int repeat = 0; repeat < 2; ++repeat) {
        std::vector<Hit> hits(rays.size());
        if (!(*engine)->intersect(rays, hits, {}).ok() || !bitwise_equal(hits, want)) ++wrong;
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(wrong.load(), 0);
  const CacheCounters c = (*engine)->cache().counters();
  EXPECT_GT(c.subtree.loads, 0u);
  EXPECT_EQ(c.subtree.rejected(), 0u);
  EXPECT_LE(c.peak_resident_bytes, options.cache_bytes);
}

TEST(SubtreeTierEngine, EmbreeWithASubtreeDirectoryIsAnError) {
  const auto scene = testing::pack_test_scene({"gen:sphere?level=2"}, 100);
  testing::TempDir tier;
  EngineOptions options;
  options.brick_accel = "embree";
  options.subtree_dir = tier.path();
  auto engine = QueryEngine::open(scene->path, options);
  ASSERT_FALSE(engine.ok());
  EXPECT_EQ(engine.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(engine.status().message().find("embree"), std::string::npos) << engine.status().message();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
