// The engine with brick proxies against the engine without: answers must be
// bitwise identical (closest and any hit) on every test scene, for
// incoherent and axis-parallel rays, across budgets, reordering and thread
// counts, while proxies skip a share of the brick visits.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>

#include "core/proxy/proxy_file.h"
#include "core/query/query_engine.h"
#include "core/store/scene_packer.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;

using Scene = testing::PackedScene;

std::unique_ptr<Scene> pack(const std::vector<std::string>& inputs, uint32_t brick_triangles) {
  return testing::pack_test_scene(inputs, brick_triangles);
}

Vec3f random_in(std::mt19937_64& rng, const Aabb& box, float grow) {
  return testing::random_point_in(rng, box, grow);
}

// Incoherent rays (from around and inside the box, aimed through it, some
// with a limited segment), then axis-parallel ones (two exact zeros, either
// sign), from random points.
std::vector<Ray> test_rays(const Aabb& box, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    Ray& r = rays[i];
    r.origin = random_in(rng, box, i % 3 == 0 ? 0.0f : 0.5f);
    if (i % 2 == 0) {
      r.direction = random_in(rng, box, 0.0f) - r.origin;
      if (r.direction == Vec3f(0, 0, 0)) r.direction = {0, 0, 1};
      if (i % 7 == 0) r.tfar = 0.5f;  // ends halfway to its target
      if (i % 11 == 0) r.tnear = 0.25f;
    } else {
      // From outside the box (one unit beyond a face), or from inside it.
      const int axis = static_cast<int>(i / 2 % 3);
      const bool up = (i / 6) % 2 != 0;
      Vec3f d(0, 0, 0);
      d[axis] = up ? 1.0f : -1.0f;
      r.direction = d;
      if (i % 5 != 0) r.origin[axis] = up ? box.lo[axis] - 1 : box.hi[axis] + 1;
      if (i % 7 == 1) r.tfar = 1 + 0.5f * box.extent()[axis];
    }
  }
  return rays;
}

std::unique_ptr<QueryEngine> engine(const Scene& scene, bool proxies, uint64_t budget = uint64_t{1} << 30) {
  EngineOptions options;
  options.cache_bytes = budget;
  options.proxies = proxies;
  auto e = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(e.ok()) << e.status().to_string();
  return std::move(e).value();
}

std::vector<Hit> intersect(QueryEngine& e, const std::vector<Ray>& rays, bool reorder = true,
                           QueryStats* stats = nullptr) {
  std::vector<Hit> hits(rays.size());
  QueryOptions options;
  options.reorder = reorder;
  const Status s = e.intersect(rays, hits, options, stats);
  EXPECT_TRUE(s.ok()) << s.to_string();
  return hits;
}

std::vector<uint8_t> occluded(QueryEngine& e, const std::vector<Ray>& rays, QueryStats* stats = nullptr) {
  std::vector<uint8_t> out(rays.size());
  const Status s = e.occluded(rays, out, QueryOptions{}, stats);
  EXPECT_TRUE(s.ok()) << s.to_string();
  return out;
}

::testing::AssertionResult same_hits(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  if (a.size() != b.size()) return ::testing::AssertionFailure() << "sizes differ";
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::memcmp(&a[i], &b[i], sizeof(Hit)) != 0) {
      return ::testing::AssertionFailure()
             << "ray " << i << ": t " << a[i].t << " vs " << b[i].t << ", primitive " << a[i].primitive_id
             << " vs " << b[i].primitive_id;
    }
  }
  return ::testing::AssertionSuccess();
}

uint64_t one_brick_budget(const QueryEngine& e) {
  uint64_t most = 0;
  for (const auto& b : e.store().manifest().bricks) {
    most = std::max(most, e.cache().builder().reserve_bytes(b.triangle_count));
  }
  return most;
}

// Proxies on vs off: the same answers everywhere; returns the share skipped.
double expect_proxies_change_nothing(const Scene& scene, const std::vector<Ray>& rays) {
  auto off = engine(scene, false);
  QueryStats off_stats;
  const std::vector<Hit> expected = intersect(*off, rays, true, &off_stats);
  EXPECT_EQ(off_stats.bricks_skipped_by_proxy, 0u);
  EXPECT_EQ(off_stats.proxy_bytes, 0u);
  std::size_t hit = 0;
  for (const Hit& h : expected) hit += h.is_hit();
  EXPECT_GT(hit, rays.size() / 10) << "the test rays should hit something";

  auto on = engine(scene, true);
  QueryStats on_stats;
  EXPECT_TRUE(same_hits(intersect(*on, rays, true, &on_stats), expected));
  // Skipped bricks are exactly the visits avoided: the rest is unchanged.
  EXPECT_EQ(on_stats.brick_visits + on_stats.bricks_skipped_by_proxy, off_stats.brick_visits);
  EXPECT_GT(on_stats.proxy_bytes, 0u);
  // The budget holds the scene, so the tests wait for the builds: a brick's
  // queue is tested up to its first ray that may hit (then built and traced
  // whole), or whole (then passed over, never built).
  EXPECT_GE(on_stats.proxy_tests, on_stats.bricks_skipped_by_proxy);
  EXPECT_GT(on_stats.proxy_tests, 0u);
  EXPECT_GT(on_stats.seconds_proxy, 0.0);
  EXPECT_LE(on_stats.brick_builds, off_stats.brick_builds);

  // Ray by ray, every brick is tested, so at least as many are skipped, for
  // more tests than waiting for the builds takes.
  QueryStats serial_stats;
  EXPECT_TRUE(same_hits(intersect(*on, rays, false, &serial_stats), expected)) << "no reorder";
  EXPECT_GE(serial_stats.bricks_skipped_by_proxy, on_stats.bricks_skipped_by_proxy);
  EXPECT_EQ(serial_stats.brick_visits + serial_stats.bricks_skipped_by_proxy, off_stats.brick_visits);
  EXPECT_LT(on_stats.proxy_tests, serial_stats.proxy_tests);

  // Warm: every brick a ray needs is resident and no longer tested; only
  // bricks the proxies kept from ever being built still are.
  QueryStats warm_stats;
  EXPECT_TRUE(same_hits(intersect(*on, rays, true, &warm_stats), expected)) << "warm";
  EXPECT_LT(warm_stats.proxy_tests, on_stats.proxy_tests);
  EXPECT_EQ(warm_stats.brick_builds, 0u);
  EXPECT_EQ(warm_stats.brick_visits + warm_stats.bricks_skipped_by_proxy, off_stats.brick_visits);

  const uint64_t tiny = one_brick_budget(*on);
  for (const uint64_t budget : {tiny, 3 * tiny}) {
    auto small = engine(scene, true, budget);
    EXPECT_TRUE(same_hits(intersect(*small, rays), expected)) << "budget " << budget;
  }
  for (const int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    auto e = engine(scene, true, 2 * tiny);
    EXPECT_TRUE(same_hits(intersect(*e, rays), expected)) << threads << " threads";
  }
  // Any hit: the same flags, with tests at arrival (a budget below the scene).
  QueryStats any_on_stats;
  auto any_engine = engine(scene, true, 3 * tiny);
  EXPECT_EQ(occluded(*any_engine, rays, &any_on_stats), occluded(*off, rays));
  EXPECT_GT(any_on_stats.bricks_skipped_by_proxy, 0u);
  return static_cast<double>(serial_stats.bricks_skipped_by_proxy) / off_stats.brick_visits;
}

TEST(ProxyEngine, ACityAnswersBitwiseTheSameWithProxiesOnAndOff) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=2)&copies=50"}, 200);
  const double skipped = expect_proxies_change_nothing(*scene, test_rays(scene->bounds, 3000, 1));
  EXPECT_GT(skipped, 0.05) << skipped;
}

// With a budget that holds the scene the tests wait for the builds: a brick
// none of whose queued rays may hit it is passed over, never built, its rays
// counted as skips; the answers and the visits the skips stand for are
// those without proxies. (Fewer tests than one a ray: docs/BENCHMARKS.md.)
TEST(ProxyEngine, WithTheSceneInBudgetABrickNoQueuedRayMayHitIsNeverBuilt) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=2)&copies=50"}, 200);
  // Few rays, so that some bricks' boxes are crossed only by rays that miss them.
  const std::vector<Ray> rays = test_rays(scene->bounds, 300, 7);
  QueryStats off_stats, on_stats;
  const std::vector<Hit> expected = intersect(*engine(*scene, false), rays, true, &off_stats);
  EXPECT_TRUE(same_hits(intersect(*engine(*scene, true), rays, true, &on_stats), expected));
  EXPECT_GT(on_stats.bricks_skipped_by_proxy, 0u) << on_stats.to_json();
  EXPECT_LT(on_stats.brick_builds, off_stats.brick_builds) << on_stats.to_json();
  EXPECT_EQ(on_stats.brick_visits + on_stats.bricks_skipped_by_proxy, off_stats.brick_visits);
}

TEST(ProxyEngine, TheStadiumAnswersBitwiseTheSameWithProxiesOnAndOff) {
  // Huge enclosure triangles overlapping a dense object's bricks.
  const auto scene = pack({"gen:stadium?size=50&level=4&object=2&segments=4"}, 300);
  const double skipped = expect_proxies_change_nothing(*scene, test_rays(scene->bounds, 3000, 2));
  EXPECT_GT(skipped, 0.0) << skipped;
}

TEST(ProxyEngine, TheBunnyAnswersBitwiseTheSameWithProxiesOnAndOff) {
  const auto scene = pack({testing::model_path("stanford-bunny.obj")}, 2048);
  const double skipped = expect_proxies_change_nothing(*scene, test_rays(scene->bounds, 2000, 3));
  EXPECT_GT(skipped, 0.05) << skipped;
}

TEST(ProxyEngine, DuplicatedGeometryTiesStayTheSameWithProxies) {
  // Every hit is a tie between two copies in different bricks.
  const auto scene = pack({"gen:sphere?level=3", "gen:sphere?level=3", "gen:torus?cx=3"}, 100);
  expect_proxies_change_nothing(*scene, test_rays(scene->bounds, 3000, 4));
}

TEST(ProxyEngine, GrazingAndInPlaneRaysOverTheStadiumFloorAnswerTheSame) {
  // The stadium's floor (y = 0) in bricks of few triangles; rays skimming it at
  // angles from 1e-6 to 1e-1 rad, and rays in its plane (y = 0, dy = 0).
  const auto scene = pack({"gen:stadium?size=50&level=3&object=2&segments=16"}, 64);
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Ray> rays(3000);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Ray& r = rays[i];
    const float angle = std::pow(10.0f, -6.0f + 5.0f * u(rng));
    const float heading = 6.2831853f * u(rng);
    const float reach = 5 + 40 * u(rng);
    r.origin = {-45 + 90 * u(rng), i % 10 == 0 ? 0.0f : reach * angle, -45 + 90 * u(rng)};
    r.direction = {std::cos(heading), i % 10 == 0 ? 0.0f : -angle, std::sin(heading)};
  }
  auto off = engine(*scene, false);
  auto on = engine(*scene, true);
  QueryStats stats;
  const auto expected = intersect(*off, rays);
  EXPECT_TRUE(same_hits(intersect(*on, rays, true, &stats), expected));
  std::size_t hit = 0;
  for (const Hit& h : expected) hit += h.is_hit();
  EXPECT_GT(hit, rays.size() / 2);
  EXPECT_GT(stats.bricks_skipped_by_proxy, 0u);
}

TEST(ProxyEngine, TheEngineCachesItsProxiesInTheStoreAndRebuildsACorruptFile) {
  const auto scene = pack({"gen:sphere?level=3"}, 100);
  const std::string file = scene->path + "/" + kProxyFileName;
  EXPECT_FALSE(std::filesystem::exists(file));
  const auto rays = test_rays(scene->bounds, 500, 5);
  std::vector<Hit> expected;
  {
    auto first = engine(*scene, true);
    EXPECT_FALSE(first->proxy_report().loaded);
    EXPECT_TRUE(first->proxy_report().written);
    expected = intersect(*first, rays);
  }
  ASSERT_TRUE(std::filesystem::exists(file));
  {
    auto second = engine(*scene, true);
    EXPECT_TRUE(second->proxy_report().loaded);
    EXPECT_TRUE(same_hits(intersect(*second, rays), expected));
  }
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 1);
  {
    auto third = engine(*scene, true);
    EXPECT_FALSE(third->proxy_report().loaded);
    EXPECT_TRUE(third->proxy_report().written);
    EXPECT_TRUE(same_hits(intersect(*third, rays), expected));
  }
  EngineOptions bad;
  bad.proxy_config.resolution = 0;
  const auto refused = QueryEngine::open(scene->path, bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  // Proxies off: nothing is read or written.
  std::filesystem::remove(file);
  auto off = engine(*scene, false);
  EXPECT_EQ(off->proxies(), nullptr);
  EXPECT_FALSE(std::filesystem::exists(file));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
