// A scene several times the cache budget, served by the real `outcore trace`
// with rays that touch every brick (issue 6, "bounded memory, proven", at CI
// scale): the answers are bitwise the unlimited run's; the engine's accounted
// peak never exceeds the budget in any batch; and the process's peak RSS
// stays within the budget plus the fixed overhead docs/BENCHMARKS.md states,
// while the unlimited run's does not (so the bound says something). Both
// ways bricks live in memory: Embree bricks built on the heap, and bvh bricks
// loaded from the subtree tier as copies of their files (released on
// eviction).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "core/store/scene_store.h"
#include "tests/support/json_fields.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::count_of;
using testing::json_uint;
using testing::read_file_bytes;
using testing::SubprocessResult;
using testing::TempDir;

constexpr uint64_t kMiB = uint64_t{1} << 20;
constexpr std::size_t kRaysPerBrick = 400;
constexpr std::size_t kRandomRays = 40'000;

// The stated bound (docs/BENCHMARKS.md, "Out of core"): budget + the process
// and its libraries + per-ray state of the batch + proxies + what the
// allocator keeps of freed bricks under eviction churn + (with the tier) the
// evicted bricks' pages queued for release.
[[maybe_unused]] uint64_t rss_allowance(uint64_t budget_bytes, std::size_t rays, std::size_t bricks,
                                        bool tier) {
  // The tier's file reads (two threads loading at once) and the allocator's
  // arenas: its runs peaked at 129-156 MiB at a 36 MiB budget (unlimited:
  // 171-176 MiB), hence 44 MiB for it.
  return budget_bytes + 60 * kMiB + 160 * rays + 10 * 1024 * bricks + budget_bytes * 25 / 100 +
         (tier ? 44 * kMiB : 0);
}

class OutOfCoreCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    store_ = dir_->file("city");
    // 2 M triangles in 80 bricks: ~270 MiB built under Embree, ~190 under bvh.
    const SubprocessResult packed =
        outcore({"pack", "gen:city?of=(gen:sphere?level=4)&copies=400", "-o", store_, "-q", "--no-sync"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    auto store = SceneStore::open(store_);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    const Manifest& manifest = (*store)->manifest();
    brick_count_ = manifest.bricks.size();
    // Rays from around the scene at random points of each brick's box, so
    // every brick is visited, and random rays through the scene.
    std::mt19937 rng(6);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays = testing::make_test_rays(manifest.bounds, kRandomRays, 66);
    const Vec3f scene = manifest.bounds.extent();
    for (const BrickRecord& brick : manifest.bricks) {
      const Vec3f e = brick.bounds.extent();
      for (std::size_t i = 0; i < kRaysPerBrick; ++i) {
        const Vec3f to(brick.bounds.lo.x + unit(rng) * e.x, brick.bounds.lo.y + unit(rng) * e.y,
                       brick.bounds.lo.z + unit(rng) * e.z);
        const Vec3f from(manifest.bounds.lo.x + (unit(rng) * 2 - 0.5f) * scene.x,
                         manifest.bounds.hi.y + scene.y + 1.0f,
                         manifest.bounds.lo.z + (unit(rng) * 2 - 0.5f) * scene.z);
        Ray ray;
        ray.origin = from;
        ray.direction = Vec3f(to.x - from.x, to.y - from.y, to.z - from.z);
        rays.push_back(ray);
      }
    }
    ray_count_ = rays.size();
    rays_path_ = dir_->file("rays.npy");
    ASSERT_TRUE(write_rays_npy(rays_path_, rays).ok());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  static SubprocessResult outcore(std::vector<std::string> args) {
    return testing::run_outcore(std::move(args), std::chrono::milliseconds(300'000));
  }

  // Traces the suite's rays at `cache_mb` with `extra` options, `repeat`
  // batches; returns the run and sets *stats to its --stats-json (one object
  // per batch: json_uint(*stats, key, batch)).
  SubprocessResult trace(const std::string& out, uint64_t cache_mb, int repeat,
                         std::vector<std::string> extra, std::string* stats) {
    const std::string json = out + ".json";
    std::vector<std::string> args{"trace",        store_, "--rays",     rays_path_,
                                  "-o",           out,    "--cache-mb", std::to_string(cache_mb),
                                  "--threads",    "2",    "--repeat",   std::to_string(repeat),
                                  "--stats-json", json};
    args.insert(args.end(), extra.begin(), extra.end());
    SubprocessResult r = outcore(args);
    *stats = read_file_bytes(json);
    return r;
  }

  void expect_bounded(std::vector<std::string> accel, bool tier) {
    TempDir out;
    std::string unlimited_stats;
    const std::string reference = out.file("unlimited.npy");
    const SubprocessResult unlimited = trace(reference, 65536, 1, accel, &unlimited_stats);
    ASSERT_TRUE(unlimited.succeeded()) << unlimited.describe();
    ASSERT_EQ(count_of(unlimited_stats, "\"brick_builds\""), 1u) << unlimited_stats;
    ASSERT_EQ(json_uint(unlimited_stats, "brick_builds"), brick_count_) << "the rays touch every brick";
    const uint64_t built = json_uint(unlimited_stats, "peak_bytes_resident");

    const uint64_t budget_mb = built / 4 / kMiB;
    ASSERT_GE(budget_mb, 16u) << "the scene is too small for the test";
    std::vector<std::string> extra = accel;
    if (tier) extra.insert(extra.end(), {"--subtree-dir", out.file("tier")});
    std::string stats;
    const std::string hits = out.file("budget.npy");
    const SubprocessResult budgeted = trace(hits, budget_mb, 2, extra, &stats);
    ASSERT_TRUE(budgeted.succeeded()) << budgeted.describe();
    ASSERT_EQ(count_of(stats, "\"brick_builds\""), 2u) << stats;
    EXPECT_EQ(read_file_bytes(hits), read_file_bytes(reference))
        << "answers under a quarter budget = unlimited";
    uint64_t evictions = 0;
    for (int batch = 0; batch < 2; ++batch) {
      EXPECT_LE(json_uint(stats, "peak_bytes_resident", batch), budget_mb * kMiB) << "batch " << batch;
      evictions += json_uint(stats, "evictions", batch);
    }
    EXPECT_GT(evictions, brick_count_) << "the scene is several times the budget";
    if (tier) {
      EXPECT_GT(json_uint(stats, "subtree_loads", 1), 0u) << stats;
    }
#ifndef OUTCORE_SANITIZE_BUILD  // sanitizer shadow memory and quarantine dwarf the bound
    const uint64_t allowance = rss_allowance(budget_mb * kMiB, ray_count_, brick_count_, tier);
    EXPECT_LE(budgeted.peak_rss_bytes, allowance)
        << "peak RSS " << budgeted.peak_rss_bytes / kMiB << " MiB at a " << budget_mb << " MiB budget";
    EXPECT_GT(unlimited.peak_rss_bytes, allowance) << "the unlimited run (" << unlimited.peak_rss_bytes / kMiB
                                                   << " MiB) fits the bound too: it proves nothing";
#endif
  }

  static TempDir* dir_;
  static std::string store_;
  static std::string rays_path_;
  static std::size_t brick_count_;
  static std::size_t ray_count_;
};

TempDir* OutOfCoreCli::dir_ = nullptr;
std::string OutOfCoreCli::store_;
std::string OutOfCoreCli::rays_path_;
std::size_t OutOfCoreCli::brick_count_ = 0;
std::size_t OutOfCoreCli::ray_count_ = 0;

TEST_F(OutOfCoreCli, EmbreeBricksAtAQuarterBudgetAnswerTheSameWithinBudgetPlusOverhead) {
  expect_bounded({}, false);
}

TEST_F(OutOfCoreCli, TierLoadedBvhBricksAtAQuarterBudgetAnswerTheSameWithinBudgetPlusOverhead) {
  expect_bounded({"--brick-accel", "bvh"}, true);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
