#include "core/cache/brick_cache.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <latch>
#include <limits>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/cache/eviction_policy.h"
#include "core/store/scene_packer.h"
#include "core/store/scene_store.h"
#include "core/store/store_format.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr uint64_t kUnlimited = std::numeric_limits<uint64_t>::max() / 4;

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// ---------------------------------------------------------------------------
// A test double of the BrickBuilder interface, used only where the builder's
// own work does not matter (eviction order, single flight with a slow build,
// the overrun path): it keeps the real loaded BrickData and claims
// bytes_per_triangle bytes per triangle.
class CountingAccel final : public BrickAccel {
 public:
  CountingAccel(BrickData data, uint64_t bytes) : data_(std::move(data)), bytes_(bytes) {}
  void intersect(std::span<const uint32_t>, const Ray*, Hit*) const override {}
  void occluded(std::span<const uint32_t>, const Ray*, uint8_t*) const override {}
  void all_hits(std::span<const uint32_t>, const Ray*, std::vector<RayHitRecord>&) const override {}
  void closest_points(std::span<const uint32_t>, const Vec3f*, ClosestPoint*) const override {}
  uint64_t memory_bytes() const override { return bytes_; }
  double build_seconds() const override { return 0.0; }
  uint32_t triangle_count() const override { return static_cast<uint32_t>(data_.triangles.size()); }

 private:
  BrickData data_;
  uint64_t bytes_;
};

struct CountingBuilderConfig {
  uint64_t bytes_per_triangle = 44;
  uint64_t reserve_per_triangle = 44;
  std::chrono::milliseconds delay{0};  // per build, to widen race windows
};

class CountingBuilder final : public BrickBuilder {
 public:
  explicit CountingBuilder(CountingBuilderConfig config = {}) : config_(config) {}
  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override {
    if (config_.delay.count() > 0) std::this_thread::sleep_for(config_.delay);
    builds_->fetch_add(1);
    const uint64_t bytes = brick.triangles.size() * config_.bytes_per_triangle;
    return std::unique_ptr<BrickAccel>(std::make_unique<CountingAccel>(std::move(brick), bytes));
  }
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return triangle_count * config_.reserve_per_triangle;
  }
  const std::string& name() const override {
    static const std::string kName = "counting";
    return kName;
  }
  // Shared so the test can read it after the cache owns the builder.
  std::shared_ptr<std::atomic<int>> builds() const { return builds_; }

 private:
  CountingBuilderConfig config_;
  std::shared_ptr<std::atomic<int>> builds_ = std::make_shared<std::atomic<int>>(0);
};

// ---------------------------------------------------------------------------

std::unique_ptr<BrickBuilder> embree_builder() {
  auto builder = make_brick_builder("embree", {});
  if (!builder.ok()) {
    ADD_FAILURE() << builder.status().to_string();
    return nullptr;
  }
  return std::move(builder).value();
}

std::unique_ptr<EvictionPolicy> lru() {
  auto policy = make_eviction_policy("lru");
  if (!policy.ok()) {
    ADD_FAILURE() << policy.status().to_string();
    return nullptr;
  }
  return std::move(policy).value();
}

// One small store (gen:sphere level 5: 20480 triangles in bricks of <= 512),
// packed once for the whole suite.
class BrickCacheTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    PackOptions options;
    options.inputs = {"gen:sphere?level=5"};
    options.output = dir_->file("scene");
    options.brick_triangles = 512;
    options.sync = false;
    const auto summary = pack_scene(options);
    ASSERT_TRUE(summary.ok()) << summary.status().to_string();
    auto store = SceneStore::open(options.output);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    store_ = new std::shared_ptr<const SceneStore>(std::move(store).value());
  }
  static void TearDownTestSuite() {
    delete store_;
    store_ = nullptr;
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(store_, nullptr);
    ASSERT_GE(store().brick_count(), 16u);
  }

  static const SceneStore& store() { return **store_; }
  static const std::shared_ptr<const SceneStore>& store_ptr() { return *store_; }
  static uint32_t triangles(uint32_t brick) { return store().manifest().bricks[brick].triangle_count; }

  static std::unique_ptr<BrickCache> make_cache(std::unique_ptr<BrickBuilder> builder, uint64_t budget,
                                                std::shared_ptr<const SceneStore> store = nullptr) {
    return std::make_unique<BrickCache>(store ? std::move(store) : store_ptr(), std::move(builder), lru(),
                                        budget);
  }

  // The largest reservation over all bricks under `builder`.
  static uint64_t max_reservation(const BrickBuilder& builder) {
    uint64_t most = 0;
    for (uint32_t b = 0; b < store().brick_count(); ++b)
      most = std::max(most, builder.reserve_bytes(triangles(b)));
    return most;
  }

  // True bytes of every brick under the embree builder (built once, unlimited budget).
  static std::vector<uint64_t> true_bytes() {
    static const std::vector<uint64_t> bytes = [] {
      std::vector<uint64_t> out;
      auto cache = make_cache(embree_builder(), kUnlimited);
      for (uint32_t b = 0; b < store().brick_count(); ++b) {
        auto pin = cache->acquire(b);
        EXPECT_TRUE(pin.ok()) << pin.status().to_string();
        out.push_back(pin.ok() ? pin->accel().memory_bytes() : 0);
      }
      return out;
    }();
    return bytes;
  }

  static testing::TempDir* dir_;
  static std::shared_ptr<const SceneStore>* store_;
};

testing::TempDir* BrickCacheTest::dir_ = nullptr;
std::shared_ptr<const SceneStore>* BrickCacheTest::store_ = nullptr;

TEST_F(BrickCacheTest, BudgetOfOneBrickBuildsEachAndEvictsThePrevious) {
  auto builder = embree_builder();
  ASSERT_NE(builder, nullptr);
  const uint64_t budget = max_reservation(*builder);
  auto cache = make_cache(std::move(builder), budget);
  const uint32_t n = store().brick_count();

  // A model of the cache: resident bricks, least recently used first, with
  // their true bytes. Before building, the least recently used go until the
  // new brick's reservation fits beside what is left.
  std::vector<std::pair<uint32_t, uint64_t>> model;
  const auto model_bytes = [&] {
    uint64_t sum = 0;
    for (const auto& [brick, bytes] : model) sum += bytes;
    return sum;
  };
  uint64_t bytes_built = 0;
  uint64_t expected_evictions = 0;
  for (uint32_t b = 0; b < n; ++b) {
    EXPECT_FALSE(cache->is_resident(b));
    const uint64_t reservation = cache->builder().reserve_bytes(triangles(b));
    while (!model.empty() && model_bytes() + reservation > budget) {
      model.erase(model.begin());
      ++expected_evictions;
    }
    auto pin = cache->acquire(b);
    ASSERT_TRUE(pin.ok()) << pin.status().to_string();
    EXPECT_EQ(pin->brick_id(), b);
    EXPECT_FALSE(pin->was_hit());
    EXPECT_EQ(pin->accel().triangle_count(), triangles(b));
    EXPECT_TRUE(cache->is_resident(b));
    const uint64_t bytes = pin->accel().memory_bytes();
    EXPECT_GT(bytes, 0u);
    EXPECT_LE(bytes, reservation);
    bytes_built += bytes;
    model.emplace_back(b, bytes);
    // Exactly the modelled bricks are resident.
    for (uint32_t earlier = 0; earlier < b; ++earlier) {
      const bool modelled =
          std::any_of(model.begin(), model.end(), [&](const auto& e) { return e.first == earlier; });
      EXPECT_EQ(cache->is_resident(earlier), modelled) << "brick " << earlier << " after acquiring " << b;
    }
    const CacheCounters c = cache->counters();
    EXPECT_EQ(c.resident_bytes, model_bytes());
    EXPECT_LE(c.peak_resident_bytes, budget);
  }
  EXPECT_GE(expected_evictions, n / 2) << "the budget should hold about one brick";

  CacheCounters c = cache->counters();
  EXPECT_EQ(c.builds, n);
  EXPECT_EQ(c.misses, n);
  EXPECT_EQ(c.hits, 0u);
  EXPECT_EQ(c.evictions, expected_evictions);
  EXPECT_EQ(c.resident_bricks, model.size());
  EXPECT_EQ(c.bytes_built, bytes_built);
  EXPECT_GT(c.build_seconds, 0.0);
  EXPECT_LE(c.peak_resident_bytes, budget);
  EXPECT_EQ(c.reservation_overruns, 0u);

  // Re-acquiring the resident brick is a hit, twice, and builds nothing.
  for (int i = 0; i < 2; ++i) {
    auto pin = cache->acquire(n - 1);
    ASSERT_TRUE(pin.ok());
    EXPECT_TRUE(pin->was_hit());
    EXPECT_EQ(pin->accel().triangle_count(), triangles(n - 1));
  }
  c = cache->counters();
  EXPECT_EQ(c.hits, 2u);
  EXPECT_EQ(c.misses, n);
  EXPECT_EQ(c.builds, n);
  EXPECT_EQ(c.resident_bytes, model_bytes());
}

TEST_F(BrickCacheTest, EvictsTheLeastRecentlyUsedBrick) {
  // Four bricks; B the largest, so the other three fit once B is gone.
  std::vector<uint32_t> four = {0, 1, 2, 3};
  std::sort(four.begin(), four.end(), [](uint32_t x, uint32_t y) { return triangles(x) > triangles(y); });
  const uint32_t b = four[0], a = four[1], c = four[2], d = four[3];
  const uint64_t budget = 44 * (uint64_t{triangles(a)} + triangles(b) + triangles(c));
  auto cache = make_cache(std::make_unique<CountingBuilder>(), budget);

  for (uint32_t brick : {a, b, c}) ASSERT_TRUE(cache->acquire(brick).ok());
  ASSERT_TRUE(cache->acquire(a).ok());  // A is now the most recently used; B the least
  EXPECT_EQ(cache->counters().evictions, 0u);
  ASSERT_TRUE(cache->acquire(d).ok());
  EXPECT_EQ(cache->counters().evictions, 1u);
  EXPECT_FALSE(cache->is_resident(b));
  for (uint32_t brick : {a, c, d}) EXPECT_TRUE(cache->is_resident(brick)) << brick;
  EXPECT_LE(cache->counters().peak_resident_bytes, budget);
}

TEST_F(BrickCacheTest, PinnedBrickIsNeverEvictedAndTheNextBuildWaitsForItsRelease) {
  auto builder = embree_builder();
  ASSERT_NE(builder, nullptr);
  // B: the largest brick; A: another. The budget holds B's reservation plus
  // half of A's true bytes, so B can only be built once A is gone.
  uint32_t b = 0;
  for (uint32_t i = 1; i < store().brick_count(); ++i) {
    if (triangles(i) > triangles(b)) b = i;
  }
  const uint32_t a = b == 0 ? 1 : 0;
  const uint64_t true_a = true_bytes()[a];
  const uint64_t budget = builder->reserve_bytes(triangles(b)) + true_a / 2;
  ASSERT_GE(budget, builder->reserve_bytes(triangles(a)));
  auto cache = make_cache(std::move(builder), budget);

  auto pin_a = cache->acquire(a);
  ASSERT_TRUE(pin_a.ok()) << pin_a.status().to_string();
  std::atomic<bool> b_done{false};
  auto b_result = std::async(std::launch::async, [&] {
    auto pin = cache->acquire(b);
    b_done = true;
    return pin;
  });

  std::this_thread::sleep_for(200ms);
  EXPECT_FALSE(b_done.load()) << "B was built while pinned A left no room";
  EXPECT_TRUE(cache->is_resident(a));
  EXPECT_FALSE(cache->is_resident(b));
  EXPECT_EQ(cache->counters().builds, 1u);
  EXPECT_EQ(cache->counters().evictions, 0u);
  EXPECT_EQ(pin_a->accel().triangle_count(), triangles(a));  // still usable

  pin_a->release();
  ASSERT_EQ(b_result.wait_for(10s), std::future_status::ready) << "B never got room after A's release";
  auto pin_b = b_result.get();
  ASSERT_TRUE(pin_b.ok()) << pin_b.status().to_string();
  EXPECT_EQ(pin_b->brick_id(), b);
  EXPECT_EQ(pin_b->accel().triangle_count(), triangles(b));
  EXPECT_FALSE(cache->is_resident(a));
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.builds, 2u);
  EXPECT_EQ(c.evictions, 1u);
  EXPECT_LE(c.peak_resident_bytes, budget);
}

TEST_F(BrickCacheTest, ConcurrentAcquirersOfAnAbsentBrickShareOneBuild) {
  constexpr int kThreads = 8;
  for (const bool slow : {false, true}) {
    SCOPED_TRACE(slow ? "slow test builder" : "embree builder");
    std::unique_ptr<BrickBuilder> builder;
    std::shared_ptr<std::atomic<int>> double_builds;
    if (slow) {
      auto counting = std::make_unique<CountingBuilder>(CountingBuilderConfig{.delay = 150ms});
      double_builds = counting->builds();
      builder = std::move(counting);
    } else {
      builder = embree_builder();
      ASSERT_NE(builder, nullptr);
    }
    auto cache = make_cache(std::move(builder), kUnlimited);
    const uint32_t brick = 3;
    std::latch start(kThreads);
    std::latch acquired(kThreads);
    std::vector<const BrickAccel*> accels(kThreads, nullptr);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        start.arrive_and_wait();
        auto pin = cache->acquire(brick);
        if (pin.ok()) accels[t] = &pin->accel();
        acquired.arrive_and_wait();  // all pins held at once
      });
    }
    for (auto& thread : threads) thread.join();
    const CacheCounters c = cache->counters();
    EXPECT_EQ(c.builds, 1u);
    EXPECT_EQ(c.hits + c.misses, uint64_t{kThreads});
    if (slow) {
      EXPECT_EQ(double_builds->load(), 1);
      EXPECT_GE(c.misses, 2u) << "nobody waited for the 150 ms build";
    }
    for (int t = 0; t < kThreads; ++t) {
      ASSERT_NE(accels[t], nullptr) << t;
      EXPECT_EQ(accels[t], accels[0]);
    }
    EXPECT_EQ(accels[0]->triangle_count(), triangles(brick));
  }
}

TEST_F(BrickCacheTest, RandomConcurrentAcquisitionsKeepTheBudgetAndTheCounters) {
  auto builder = embree_builder();
  ASSERT_NE(builder, nullptr);
  const uint64_t budget = 3 * max_reservation(*builder);
  auto cache = make_cache(std::move(builder), budget);
  const uint32_t bricks = std::min<uint32_t>(store().brick_count(), 24);
  constexpr int kThreads = 6;
  constexpr int kAcquisitions = 150;

  std::atomic<bool> done{false};
  std::atomic<uint64_t> sampled_max{0};
  std::atomic<uint64_t> samples{0};
  std::thread sampler([&] {
    while (!done.load()) {
      const CacheCounters c = cache->counters();
      uint64_t seen = sampled_max.load();
      while (c.resident_bytes > seen && !sampled_max.compare_exchange_weak(seen, c.resident_bytes)) {
      }
      samples.fetch_add(1);
      std::this_thread::yield();
    }
  });

  std::atomic<uint64_t> hits{0}, misses{0}, wrong{0}, failed{0};
  std::vector<std::future<void>> workers;
  for (int t = 0; t < kThreads; ++t) {
    workers.push_back(std::async(std::launch::async, [&, t] {
      std::mt19937 rng(1234 + t);
      // Skewed towards a few hot bricks so there are hits as well as misses.
      std::uniform_int_distribution<uint32_t> any(0, bricks - 1);
      std::uniform_int_distribution<uint32_t> hot(0, 3);
      for (int i = 0; i < kAcquisitions; ++i) {
        const uint32_t brick = (rng() % 2 == 0) ? hot(rng) : any(rng);
        auto pin = cache->acquire(brick);
        if (!pin.ok()) {
          failed.fetch_add(1);
          ADD_FAILURE() << pin.status().to_string();
          continue;
        }
        if (pin->brick_id() != brick || pin->accel().triangle_count() != triangles(brick)) wrong.fetch_add(1);
        (pin->was_hit() ? hits : misses).fetch_add(1);
        if (rng() % 4 == 0) std::this_thread::sleep_for(50us);  // hold the pin a little
      }
    }));
  }
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  for (auto& worker : workers) {
    if (worker.wait_until(deadline) != std::future_status::ready) {
      // A deadlock cannot be unwound from here.
      std::fprintf(stderr, "BrickCacheTest: workers still running after 60 s (deadlock?)\n");
      std::abort();
    }
  }
  done = true;
  sampler.join();

  const CacheCounters c = cache->counters();
  EXPECT_EQ(failed.load(), 0u);
  EXPECT_EQ(wrong.load(), 0u);
  EXPECT_EQ(c.hits, hits.load());
  EXPECT_EQ(c.misses, misses.load());
  EXPECT_EQ(c.hits + c.misses, uint64_t{kThreads} * kAcquisitions);
  EXPECT_GT(c.hits, 0u);
  EXPECT_LE(c.builds, c.misses);
  EXPECT_GT(c.evictions, 0u) << "the budget was meant to be small";
  EXPECT_EQ(c.evictions + c.resident_bricks, c.builds);
  EXPECT_LE(c.peak_resident_bytes, budget);
  EXPECT_LE(sampled_max.load(), budget);
  // At least one sample while the workers ran (how many depends on the
  // machine's load: CI machines are shared).
  EXPECT_GT(samples.load(), 0u);
  EXPECT_EQ(c.reservation_overruns, 0u);

  // Resident bytes are exactly the resident bricks' true bytes.
  uint64_t resident = 0;
  uint32_t resident_bricks = 0;
  for (uint32_t b = 0; b < bricks; ++b) {
    if (!cache->is_resident(b)) continue;
    auto pin = cache->acquire(b);
    ASSERT_TRUE(pin.ok());
    EXPECT_TRUE(pin->was_hit());
    resident += pin->accel().memory_bytes();
    ++resident_bricks;
  }
  EXPECT_EQ(cache->counters().resident_bytes, resident);
  EXPECT_EQ(cache->counters().resident_bricks, resident_bricks);
}

TEST_F(BrickCacheTest, BrickLargerThanTheBudgetIsResourceExhaustedNamingIt) {
  auto builder = embree_builder();
  ASSERT_NE(builder, nullptr);
  uint32_t big = 0, small = 0;
  for (uint32_t i = 1; i < store().brick_count(); ++i) {
    if (triangles(i) > triangles(big)) big = i;
    if (triangles(i) < triangles(small)) small = i;
  }
  ASSERT_LT(triangles(small), triangles(big));
  const uint64_t budget = builder->reserve_bytes(triangles(big)) - 1;
  ASSERT_LE(builder->reserve_bytes(triangles(small)), budget);
  auto cache = make_cache(std::move(builder), budget);

  for (int attempt = 0; attempt < 2; ++attempt) {
    auto pin = cache->acquire(big);
    ASSERT_FALSE(pin.ok());
    EXPECT_EQ(pin.status().code(), StatusCode::kResourceExhausted);
    const std::string& message = pin.status().message();
    EXPECT_TRUE(contains(message, "brick " + std::to_string(big) + " needs up to")) << message;
    EXPECT_TRUE(contains(message, "MiB")) << message;
    EXPECT_TRUE(contains(message, std::to_string(budget) + " bytes")) << message;
  }
  // Nothing was reserved or counted, and smaller bricks still build.
  EXPECT_EQ(cache->counters().resident_bytes, 0u);
  auto pin = cache->acquire(small);
  ASSERT_TRUE(pin.ok()) << pin.status().to_string();
  EXPECT_EQ(pin->accel().triangle_count(), triangles(small));
  EXPECT_EQ(cache->counters().builds, 1u);
  EXPECT_EQ(cache->counters().hits + cache->counters().misses, 1u);
}

TEST_F(BrickCacheTest, CorruptedBrickIsDataLossAndTheCacheStaysUsable) {
  testing::TempDir dir;
  const std::string copy = dir.file("scene");
  fs::copy(store().directory(), copy, fs::copy_options::recursive);
  const uint32_t bad = store().brick_count() / 2;
  {
    const BrickRecord& record = store().manifest().bricks[bad];
    std::fstream file(copy + "/" + kBrickDataFileName, std::ios::in | std::ios::out | std::ios::binary);
    ASSERT_TRUE(file.good());
    const auto at = static_cast<std::streamoff>(record.offset + sizeof(BrickHeader) + 100);
    file.seekg(at);
    char byte = 0;
    file.read(&byte, 1);
    byte = static_cast<char>(byte ^ 0x10);
    file.seekp(at);
    file.write(&byte, 1);
    ASSERT_TRUE(file.good());
  }
  auto corrupted = SceneStore::open(copy);
  ASSERT_TRUE(corrupted.ok()) << corrupted.status().to_string();
  auto builder = embree_builder();
  ASSERT_NE(builder, nullptr);
  const uint64_t budget = 4 * max_reservation(*builder);
  auto cache = make_cache(std::move(builder), budget, std::move(corrupted).value());

  const auto expect_data_loss = [&](const Expected<PinnedBrick>& pin) {
    ASSERT_FALSE(pin.ok());
    EXPECT_EQ(pin.status().code(), StatusCode::kDataLoss) << pin.status().to_string();
    EXPECT_TRUE(contains(pin.status().message(), "brick " + std::to_string(bad) + " "))
        << pin.status().message();
  };
  expect_data_loss(cache->acquire(bad));
  EXPECT_FALSE(cache->is_resident(bad));
  EXPECT_EQ(cache->counters().resident_bytes, 0u) << "the failed build's reservation leaked";

  // Other bricks (more than the budget holds, so evictions happen) still work.
  uint32_t built = 0;
  for (uint32_t b = 0; b < store().brick_count(); ++b) {
    if (b == bad) continue;
    auto pin = cache->acquire(b);
    ASSERT_TRUE(pin.ok()) << pin.status().to_string();
    EXPECT_EQ(pin->accel().triangle_count(), triangles(b));
    ++built;
  }
  // Concurrent acquirers of the corrupted brick all get the error, none hangs.
  std::vector<std::future<Expected<PinnedBrick>>> tries;
  for (int t = 0; t < 4; ++t)
    tries.push_back(std::async(std::launch::async, [&] { return cache->acquire(bad); }));
  for (auto& attempt : tries) {
    ASSERT_EQ(attempt.wait_for(10s), std::future_status::ready);
    expect_data_loss(attempt.get());
  }
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.builds, built);
  EXPECT_EQ(c.hits + c.misses, built);
  EXPECT_LE(c.peak_resident_bytes, budget);
  EXPECT_GT(c.evictions, 0u);
  auto again = cache->acquire(0 == bad ? 1 : 0);
  EXPECT_TRUE(again.ok());
}

TEST_F(BrickCacheTest, BrickBeyondTheStoreIsOutOfRange) {
  auto cache = make_cache(std::make_unique<CountingBuilder>(), kUnlimited);
  auto pin = cache->acquire(store().brick_count());
  ASSERT_FALSE(pin.ok());
  EXPECT_EQ(pin.status().code(), StatusCode::kOutOfRange);
  EXPECT_TRUE(contains(pin.status().message(), "brick " + std::to_string(store().brick_count())));
}

TEST_F(BrickCacheTest, PinsMoveAndReleaseOnce) {
  auto cache =
      make_cache(std::make_unique<CountingBuilder>(), 44 * uint64_t{std::max(triangles(0), triangles(1))});
  auto first = cache->acquire(0);
  ASSERT_TRUE(first.ok());
  PinnedBrick moved = std::move(first).value();
  EXPECT_EQ(moved.brick_id(), 0u);
  PinnedBrick other;
  other = std::move(moved);
  moved.release();  // empty: no-op
  // Still pinned: brick 1 cannot evict brick 0 and waits, so try from a thread.
  auto waiting = std::async(std::launch::async, [&] { return cache->acquire(1); });
  EXPECT_EQ(waiting.wait_for(100ms), std::future_status::timeout);
  other.release();
  other.release();  // twice: no-op
  ASSERT_EQ(waiting.wait_for(10s), std::future_status::ready);
  EXPECT_TRUE(waiting.get().ok());
  EXPECT_FALSE(cache->is_resident(0));
}

TEST_F(BrickCacheTest, AReservationOverrunIsCountedNotFatal) {
  // A buggy builder that reserves half of what it builds.
  auto cache = make_cache(std::make_unique<CountingBuilder>(
                              CountingBuilderConfig{.bytes_per_triangle = 88, .reserve_per_triangle = 44}),
                          kUnlimited);
  auto pin = cache->acquire(0);
  ASSERT_TRUE(pin.ok()) << pin.status().to_string();
  const CacheCounters c = cache->counters();
  EXPECT_EQ(c.reservation_overruns, 1u);
  EXPECT_EQ(c.resident_bytes, 88u * triangles(0));  // the true bytes, honestly
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore

namespace outcore {
namespace OUTCORE_UNITY_ID {

// A builder that records the demand of each build and wants a rebuild once a
// brick's expected rays reach a threshold (a stand-in for auto's choice).
class DemandBuilder final : public BrickBuilder {
 public:
  explicit DemandBuilder(uint64_t rebuild_at) : rebuild_at_(rebuild_at) {}
  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override {
    return build_for(std::move(brick), BuildDemand{});
  }
  Expected<std::unique_ptr<BrickAccel>> build_for(BrickData&& brick,
                                                  const BuildDemand& demand) const override {
    demands_->push_back(demand);
    const uint64_t bytes = brick.triangles.size() * (demand.rays_expected >= rebuild_at_ ? 60 : 40);
    return std::unique_ptr<BrickAccel>(std::make_unique<CountingAccel>(std::move(brick), bytes));
  }
  bool worth_rebuilding(const BrickAccel& accel, const BuildDemand& demand) const override {
    return demand.rays_expected >= rebuild_at_ && accel.memory_bytes() == accel.triangle_count() * 40u;
  }
  std::string_view structure_of(const BrickAccel& accel) const override {
    return accel.memory_bytes() == accel.triangle_count() * 40u ? "grid" : "bvh";
  }
  uint64_t reserve_bytes(uint32_t triangle_count) const override { return triangle_count * 60; }
  const std::string& name() const override {
    static const std::string kName = "demand";
    return kName;
  }
  std::shared_ptr<std::vector<BuildDemand>> demands() const { return demands_; }

 private:
  uint64_t rebuild_at_;
  std::shared_ptr<std::vector<BuildDemand>> demands_ = std::make_shared<std::vector<BuildDemand>>();
};

TEST_F(BrickCacheTest, RaysAreSummedPerBrickAndABrickWorthRebuildingIsRebuiltUnlessPinned) {
  auto builder = std::make_unique<DemandBuilder>(100);
  const auto demands = builder->demands();
  auto cache = make_cache(std::move(builder), kUnlimited);
  {
    auto pin = cache->acquire(3, 30);
    ASSERT_TRUE(pin.ok());
    ASSERT_EQ(demands->size(), 1u);
    EXPECT_EQ(demands->back().rays_now, 30u);
    EXPECT_EQ(demands->back().rays_expected, 30u);
    // Pinned: 30 + 80 rays would pay for a rebuild, but the brick is in use.
    auto again = cache->acquire(3, 80);
    ASSERT_TRUE(again.ok());
    EXPECT_TRUE(again->was_hit());
    EXPECT_EQ(demands->size(), 1u);
  }
  const CacheCounters before = cache->counters();
  EXPECT_EQ(before.rebuilds, 0u);
  EXPECT_EQ(before.builds_by_structure[brick_structure_index("grid")], 1u);
  // Unpinned now: the next acquisition rebuilds it for 30 + 80 + 5 rays.
  auto pin = cache->acquire(3, 5);
  ASSERT_TRUE(pin.ok());
  EXPECT_FALSE(pin->was_hit());
  ASSERT_EQ(demands->size(), 2u);
  EXPECT_EQ(demands->back().rays_expected, 115u);
  EXPECT_EQ(demands->back().rays_now, 5u);
  const CacheCounters after = cache->counters();
  EXPECT_EQ(after.rebuilds, 1u);
  EXPECT_EQ(after.builds, 2u);
  EXPECT_EQ(after.evictions, 0u);
  EXPECT_EQ(after.builds_by_structure[brick_structure_index("bvh")], 1u);
  EXPECT_EQ(after.resident_bricks, 1u);
  EXPECT_EQ(after.resident_bytes, triangles(3) * 60u);  // the old brick's bytes released
  pin->release();
  // Rays reported after the fact (the in-cache sweep) count too, and survive eviction.
  std::vector<uint64_t> rays(store().brick_count(), 0);
  rays[4] = 7;
  cache->add_rays_served(rays);
  auto other = cache->acquire(4, 1);
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(demands->back().rays_expected, 8u);
}

TEST_F(BrickCacheTest, RaysAheadRaiseTheExpectedUseOfThisAcquisitionOnly) {
  auto builder = std::make_unique<DemandBuilder>(1000);
  const auto demands = builder->demands();
  auto cache = make_cache(std::move(builder), kUnlimited);
  // 20 rays queued, 300 of the batch with the brick ahead (the 20 among them).
  ASSERT_TRUE(cache->acquire(5, 20, 300).ok());
  ASSERT_EQ(demands->size(), 1u);
  EXPECT_EQ(demands->back().rays_now, 20u);
  EXPECT_EQ(demands->back().rays_expected, 300u);
  // Fewer ahead than queued (not counted): the queue is the batch's use.
  ASSERT_TRUE(cache->acquire(6, 50, 10).ok());
  EXPECT_EQ(demands->back().rays_expected, 50u);
  // Only rays traced are summed: after 20 served, 700 ahead expect 720, below
  // the rebuild at 1000; 100 queued of 1000 ahead expect 20 + 100 + 900.
  ASSERT_TRUE(cache->acquire(5, 0, 700).ok());
  EXPECT_EQ(cache->counters().rebuilds, 0u);
  ASSERT_TRUE(cache->acquire(5, 100, 1000).ok());
  EXPECT_EQ(cache->counters().rebuilds, 1u);
  EXPECT_EQ(demands->back().rays_expected, 1020u);  // 20 + 100 served, 900 more ahead
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
