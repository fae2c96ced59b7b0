#include "core/query/query_engine.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <thread>

#include "core/accel/brute_force_reference.h"
#include "core/store/scene_packer.h"
#include "core/util/cancellation.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::TempDir;

using testing::PackedScene;

std::unique_ptr<PackedScene> pack(const std::vector<std::string>& inputs, uint32_t brick_triangles) {
  return testing::pack_test_scene(inputs, brick_triangles);
}

Vec3f random_in(std::mt19937_64& rng, const Aabb& box, float grow = 0.0f) {
  return testing::random_point_in(rng, box, grow);
}

// Rays from around and inside the box, aimed through it; some with short tfar.
std::vector<Ray> mixed_rays(const Aabb& box, std::size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f origin = random_in(rng, box, i % 3 == 0 ? 0.0f : 0.6f);
    const Vec3f target = random_in(rng, box);
    rays[i].origin = origin;
    rays[i].direction = target - origin;
    if (rays[i].direction == Vec3f(0, 0, 0)) rays[i].direction = {0, 0, 1};
    if (i % 7 == 0) rays[i].tfar = 0.5f;  // ends halfway to the target
    if (i % 11 == 0) rays[i].tnear = 0.25f;
  }
  return rays;
}

std::unique_ptr<QueryEngine> engine_for(const PackedScene& scene, uint64_t cache_bytes = uint64_t{1} << 30,
                                        bool proxies = true,
                                        const std::string& brick_accel = kDefaultBrickAccel) {
  EngineOptions options;
  options.cache_bytes = cache_bytes;
  options.proxies = proxies;
  options.brick_accel = brick_accel;
  auto engine = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  return std::move(engine).value();
}

std::vector<Hit> intersect(QueryEngine& engine, const std::vector<Ray>& rays, QueryOptions options = {},
                           QueryStats* stats = nullptr) {
  std::vector<Hit> hits(rays.size());
  const Status s = engine.intersect(rays, hits, options, stats);
  EXPECT_TRUE(s.ok()) << s.to_string();
  return hits;
}

// The batch traced in a shuffled order (seeded), its hits mapped back to
// input order.
std::vector<Hit> intersect_shuffled(QueryEngine& engine, const std::vector<Ray>& rays,
                                    const QueryOptions& options, uint64_t seed) {
  std::vector<std::size_t> order(rays.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937_64(seed));
  std::vector<Ray> shuffled(rays.size());
  for (std::size_t i = 0; i < order.size(); ++i) shuffled[i] = rays[order[i]];
  const std::vector<Hit> shuffled_hits = intersect(engine, shuffled, options);
  std::vector<Hit> unshuffled(rays.size());
  for (std::size_t i = 0; i < order.size(); ++i) unshuffled[order[i]] = shuffled_hits[i];
  return unshuffled;
}

bool bitwise_equal(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
}

// The budget that holds exactly the largest brick's reservation.
uint64_t one_brick_budget(const QueryEngine& engine) {
  uint64_t most = 0;
  for (const auto& b : engine.store().manifest().bricks) {
    most = std::max(most, engine.cache().builder().reserve_bytes(b.triangle_count));
  }
  return most;
}

// Strict mode refuses the batch with INVALID_ARGUMENT containing `message`.
void expect_strict_error(QueryEngine& engine, const std::vector<Ray>& rays, const std::string& message) {
  QueryOptions strict;
  strict.strict = true;
  std::vector<Hit> out(rays.size());
  const Status s = engine.intersect(rays, out, strict);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find(message), std::string::npos) << s.message();
}

void expect_matches_reference(const PackedScene& scene, const std::vector<Ray>& rays,
                              const std::vector<Hit>& hits) {
  std::size_t ties = 0, hits_seen = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const ReferenceHit ref = reference_closest_hit(scene.triangles, scene.ids, rays[i]);
    const Hit& h = hits[i];
    if (!ref.is_hit()) {
      // A float hit the float64 test misses can only be a graze at an edge.
      if (h.is_hit()) ++ties;
      continue;
    }
    ++hits_seen;
    if (!h.is_hit()) {
      ++ties;  // grazing an edge exactly: float may miss what float64 hits
      continue;
    }
    if (h.geometry_id != ref.geometry_id || h.primitive_id != ref.primitive_id) {
      // Only a true tie (equal distance within float precision) may differ.
      EXPECT_NEAR(h.t, ref.t, 1e-5 * std::max(1.0, ref.t)) << "ray " << i;
      ++ties;
      continue;
    }
    EXPECT_NEAR(h.t, ref.t, 1e-5 * std::max(1.0, ref.t)) << "ray " << i;
    EXPECT_NEAR(h.u, ref.u, 1e-3) << "ray " << i;
    EXPECT_NEAR(h.v, ref.v, 1e-3) << "ray " << i;
    EXPECT_NEAR(h.normal.x, ref.normal.x, 1e-4) << "ray " << i;
    EXPECT_NEAR(h.normal.y, ref.normal.y, 1e-4) << "ray " << i;
    EXPECT_NEAR(h.normal.z, ref.normal.z, 1e-4) << "ray " << i;
  }
  EXPECT_GT(hits_seen, rays.size() / 10) << "the test rays should hit something";
  EXPECT_LE(ties, rays.size() / 200) << "more disagreements than edge ties explain";
}

TEST(QueryEngine, ClosestHitsMatchTheFloat64BruteForceReferenceOnManySmallBricks) {
  const auto scene =
      pack({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5", "gen:terrain?n=24&size=6&height=0.5"}, 128);
  auto engine = engine_for(*scene);
  ASSERT_GT(engine->store().brick_count(), 40u);
  const auto rays = mixed_rays(scene->bounds, 3000, 1);
  expect_matches_reference(*scene, rays, intersect(*engine, rays));
}

TEST(QueryEngine, ClosestHitsMatchTheReferenceOnTheBunny) {
  const auto scene = pack({testing::model_path("stanford-bunny.obj")}, 4096);
  auto engine = engine_for(*scene);
  const auto rays = mixed_rays(scene->bounds, 800, 2);
  expect_matches_reference(*scene, rays, intersect(*engine, rays));
}

TEST(QueryEngine, OverlappingBricksOfAStadiumMatchTheReference) {
  // Huge enclosure triangles overlap the dense object's bricks.
  const auto scene = pack({"gen:stadium?size=50&level=4&object=2&segments=4"}, 300);
  auto engine = engine_for(*scene);
  const auto rays = mixed_rays(scene->bounds, 2000, 3);
  expect_matches_reference(*scene, rays, intersect(*engine, rays));
}

TEST(QueryEngine, AnswersAreBitwiseIdenticalAcrossBudgetsReorderingThreadsShufflingAndSplitting) {
  const auto scene = pack({"gen:sphere?level=4", "gen:city?of=(gen:sphere?level=2)&copies=30"}, 200);
  const auto rays = mixed_rays(scene->bounds, 4000, 4);
  auto unlimited = engine_for(*scene);
  const std::vector<Hit> expected = intersect(*unlimited, rays);

  const uint64_t tiny = one_brick_budget(*unlimited);
  for (const uint64_t budget : {tiny, 3 * tiny, uint64_t{1} << 30}) {
    auto engine = engine_for(*scene, budget);
    QueryStats stats;
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, {}, &stats), expected)) << "budget " << budget;
    EXPECT_LE(stats.peak_bytes_resident, budget);
    QueryOptions serial;
    serial.reorder = false;
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, serial), expected)) << "no reorder, budget " << budget;
  }
  for (const int threads : {1, 2, 4}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    auto engine = engine_for(*scene, 2 * tiny);
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays), expected)) << threads << " threads";
  }
  // Shuffled, then mapped back to input order.
  const std::vector<Hit> unshuffled = intersect_shuffled(*unlimited, rays, {}, 5);
  EXPECT_TRUE(bitwise_equal(unshuffled, expected));
  // Split into uneven batches.
  std::vector<Hit> joined;
  for (std::size_t begin = 0; begin < rays.size();) {
    const std::size_t end = std::min(rays.size(), begin + 1 + begin / 3);
    const auto part = intersect(*unlimited, std::vector<Ray>(rays.begin() + begin, rays.begin() + end));
    joined.insert(joined.end(), part.begin(), part.end());
    begin = end;
  }
  EXPECT_TRUE(bitwise_equal(joined, expected));
}

// The same sphere packed twice (geometry 0 and 1): every hit is a true tie,
// inside a brick or between bricks. Whichever copy wins, the answer is the
// same across budgets, reordering and thread counts, and it is the triangle
// (primitive id) and t the float64 reference finds.
TEST(QueryEngine, DuplicatedGeometryTiesAreAnsweredTheSameUnderAnyBudgetOrderAndThreads) {
  const auto scene = pack({"gen:sphere?level=3", "gen:sphere?level=3"}, 100);
  const auto rays = mixed_rays(scene->bounds, 3000, 9);
  auto unlimited = engine_for(*scene);
  const std::vector<Hit> expected = intersect(*unlimited, rays);
  std::size_t hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const ReferenceHit ref = reference_closest_hit(scene->triangles, scene->ids, rays[i]);
    if (!ref.is_hit() || !expected[i].is_hit()) continue;  // edge grazes: counted in the other tests
    ++hits;
    EXPECT_LE(expected[i].geometry_id, 1u) << "ray " << i;
    EXPECT_EQ(expected[i].primitive_id, ref.primitive_id) << "ray " << i;
    EXPECT_NEAR(expected[i].t, ref.t, 1e-5 * std::max(1.0, ref.t)) << "ray " << i;
  }
  EXPECT_GT(hits, rays.size() / 10);
  const uint64_t tiny = one_brick_budget(*unlimited);
  QueryOptions serial;
  serial.reorder = false;
  for (const int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    auto engine = engine_for(*scene, tiny);
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays), expected)) << threads << " threads";
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, serial), expected))
        << threads << " threads, no reorder";
  }
}

// Pinhole-camera rays at the box, row-major: whole chunks of them are
// coherent, so the brick structure traces them as packets (streams).
std::vector<Ray> camera_rays(const Aabb& box, int side) {
  const Vec3f c = box.center();
  const Vec3f e = box.extent();
  const Vec3f eye = c + Vec3f(0.4f * e.x, 0.3f * e.y, 1.5f * e.z + 1.2f * e.x);
  std::vector<Ray> rays;
  for (int y = 0; y < side; ++y) {
    for (int x = 0; x < side; ++x) {
      const Vec3f target = c + Vec3f((x + 0.5f) / side * 1.1f * e.x - 0.55f * e.x,
                                     (y + 0.5f) / side * 1.1f * e.y - 0.55f * e.y, 0.0f);
      Ray r;
      r.origin = eye;
      r.direction = target - eye;
      rays.push_back(r);
    }
  }
  return rays;
}

// Rays that run in an axis plane through the scene's middle (a zero
// direction component, origins on the plane, many with negative zeros): on
// the symmetric test meshes the plane holds mesh edges, so these rays cross
// triangles exactly at their edges and run along the faces of boxes.
std::vector<Ray> axis_plane_rays(const Aabb& box) {
  const Vec3f mid = box.center();
  const Vec3f e = box.extent();
  std::vector<Ray> rays;
  for (int k = 0; k < 64; ++k) {
    Ray r;
    r.origin = Vec3f(-0.0f, mid.y + 0.01f * e.y * (k - 32), box.lo.z - 1.0f);
    r.direction = Vec3f(k % 2 ? -0.0f : 0.0f, -0.0f, 1.0f);
    rays.push_back(r);
    r.origin = Vec3f(mid.x + 0.01f * e.x * k, -0.0f, -0.0f);
    r.direction = Vec3f(k % 3 ? -1.0f : 1.0f, -0.0f, 0.001f * k);
    rays.push_back(r);
    r.origin = Vec3f(mid.x, mid.y + 0.013f * e.y * (k - 32), mid.z);
    r.direction = Vec3f(k % 4 ? 1.0f : -1.0f, 0.0f, 0.0f);
    rays.push_back(r);
  }
  return rays;
}

// mixed_rays, then 64 x 64 camera rays, then the axis-plane rays; `generic`
// is set to the count before the axis-plane rays (the rays in general
// position).
std::vector<Ray> mixed_camera_and_in_plane_rays(const Aabb& box, std::size_t mixed, uint64_t seed,
                                                std::size_t& generic) {
  std::vector<Ray> rays = mixed_rays(box, mixed, seed);
  const std::vector<Ray> camera = camera_rays(box, 64);
  rays.insert(rays.end(), camera.begin(), camera.end());
  generic = rays.size();
  const std::vector<Ray> in_plane = axis_plane_rays(box);
  rays.insert(rays.end(), in_plane.begin(), in_plane.end());
  return rays;
}

// Duplicated triangles under camera rays: in a batch the rays go as coherent
// packets, shuffled or one by one as single rays, split into uneven batches
// as packets of other compositions. Every hit is a tie between the copies,
// and the tie rule must pick the same one (the smaller geometry id) every
// way, bitwise identically.
TEST(QueryEngine, DuplicatedGeometryUnderCoherentRaysIsBatchIndependent) {
  for (const uint32_t brick_triangles : {100000u, 150u}) {
    SCOPED_TRACE("brick triangles " + std::to_string(brick_triangles));
    const auto scene = pack({"gen:sphere?level=4", "gen:sphere?level=4"}, brick_triangles);
    const auto rays = camera_rays(scene->bounds, 96);
    auto unlimited = engine_for(*scene);
    const std::vector<Hit> expected = intersect(*unlimited, rays);
    std::size_t hits = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (!expected[i].is_hit()) continue;
      ++hits;
      EXPECT_EQ(expected[i].geometry_id, 0u) << "ray " << i;
    }
    EXPECT_GT(hits, rays.size() / 4);
    QueryOptions serial;
    serial.reorder = false;
    EXPECT_TRUE(bitwise_equal(intersect(*unlimited, rays, serial), expected)) << "one by one";
    const std::vector<Hit> unshuffled = intersect_shuffled(*unlimited, rays, {}, 11);
    EXPECT_TRUE(bitwise_equal(unshuffled, expected)) << "shuffled";
    std::vector<Hit> joined;
    for (std::size_t begin = 0; begin < rays.size();) {
      const std::size_t end = std::min(rays.size(), begin + 17 + begin / 5);
      const auto part = intersect(*unlimited, std::vector<Ray>(rays.begin() + begin, rays.begin() + end));
      joined.insert(joined.end(), part.begin(), part.end());
      begin = end;
    }
    EXPECT_TRUE(bitwise_equal(joined, expected)) << "split";
    for (const int threads : {1, 2}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      auto engine = engine_for(*scene, one_brick_budget(*unlimited));
      EXPECT_TRUE(bitwise_equal(intersect(*engine, rays), expected)) << threads << " threads, one brick";
    }
  }
}

// Camera rays over many bricks take the first upper pass eight at a time
// (upper_packet_traversal.h): the same answers bitwise as one ray at a time,
// and as the float64 reference, closest and any hit, with invalid rays and
// scattered rays among them (packets of mixed octants fall back per ray).
TEST(QueryEngine, PacketFirstPassAnswersBitwiseAsOneRayAtATime) {
  const auto scene =
      pack({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5", "gen:terrain?n=24&size=6&height=0.5"}, 128);
  auto engine = engine_for(*scene);
  ASSERT_GT(engine->store().brick_count(), 40u);
  std::vector<Ray> rays = camera_rays(scene->bounds, 72);
  const auto scattered = mixed_rays(scene->bounds, 700, 5);
  rays.insert(rays.begin() + 1000, scattered.begin(), scattered.end());
  rays[13].direction = {0, 0, 0};
  rays[2001].origin.x = std::numeric_limits<float>::infinity();
  QueryOptions single;
  single.avx_upper = false;
  QueryStats single_stats, packet_stats;
  const std::vector<Hit> expected = intersect(*engine, rays, single);
  expect_matches_reference(*scene, rays, expected);
  // Warm, so that both count the same visits (proxies test cold bricks only).
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, single, &single_stats), expected));
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, {}, &packet_stats), expected));
  EXPECT_EQ(packet_stats.brick_visits, single_stats.brick_visits);
  EXPECT_EQ(packet_stats.invalid_rays, 2u);
  EXPECT_EQ(packet_stats.rays_hit, single_stats.rays_hit);
  EXPECT_EQ(packet_stats.rays_hit,
            static_cast<uint64_t>(
                std::count_if(expected.begin(), expected.end(), [](const Hit& h) { return h.is_hit(); })));
  QueryOptions one_by_one;
  one_by_one.reorder = false;
  QueryStats one_by_one_stats;
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, one_by_one, &one_by_one_stats), expected));
  EXPECT_EQ(one_by_one_stats.rays_hit, packet_stats.rays_hit);
  EXPECT_GT(packet_stats.upper_nodes_visited, 0u);
  std::vector<uint8_t> occluded_single(rays.size()), occluded_packet(rays.size());
  ASSERT_TRUE(engine->occluded(rays, occluded_single, single).ok());
  ASSERT_TRUE(engine->occluded(rays, occluded_packet, {}).ok());
  EXPECT_EQ(occluded_packet, occluded_single);
  for (const int threads : {1, 3}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays), expected)) << threads << " threads";
  }
  // Under a budget of one brick (queues, builds, trace-ahead): still the same.
  auto tight = engine_for(*scene, one_brick_budget(*engine));
  EXPECT_TRUE(bitwise_equal(intersect(*tight, rays), expected));
}

TEST(QueryEngine, AnyHitAgreesWithClosestHitExistingForEveryRay) {
  const auto scene = pack({"gen:sphere?level=3", "gen:torus?cx=2"}, 100);
  auto engine = engine_for(*scene);
  const auto rays = mixed_rays(scene->bounds, 3000, 6);
  const auto hits = intersect(*engine, rays);
  for (const bool reorder : {true, false}) {
    std::vector<uint8_t> occluded(rays.size(), 7);
    QueryOptions options;
    options.reorder = reorder;
    QueryStats stats;
    ASSERT_TRUE(engine->occluded(rays, occluded, options, &stats).ok());
    std::size_t both = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      EXPECT_EQ(occluded[i] != 0, hits[i].is_hit()) << "ray " << i;
      both += occluded[i] != 0;
    }
    EXPECT_EQ(stats.rays_hit, both);
    EXPECT_GT(both, 0u);
  }
}

TEST(QueryEngine, RaysInsideTheSceneEndingEarlyOrStartingLateFollowTheirSegment) {
  const auto scene = pack({"gen:sphere?level=4"}, 64);
  auto engine = engine_for(*scene);
  // From the centre of the unit sphere along a unit direction near +x (clear of
  // vertices and edges, which are issue 5's watertightness stress): the surface
  // is at t = 1 within the tessellation's sag.
  const Vec3f dir = normalize(Vec3f(1.0f, 0.1234f, 0.0567f));
  std::vector<Ray> rays(4);
  for (auto& r : rays) {
    r.origin = {0, 0, 0};
    r.direction = dir;
  }
  rays[1].tfar = 0.9f;             // ends before the surface
  rays[2].tnear = 1.1f;            // starts past it
  rays[3].direction = dir * 2.0f;  // t in units of the direction's length
  const auto hits = intersect(*engine, rays);
  EXPECT_NEAR(hits[0].t, 1.0f, 5e-3f);
  EXPECT_FALSE(hits[1].is_hit());
  EXPECT_FALSE(hits[2].is_hit());
  EXPECT_EQ(hits[2].t, std::numeric_limits<float>::infinity());
  EXPECT_EQ(hits[2].primitive_id, kInvalidId);
  EXPECT_EQ(hits[2].normal, Vec3f(0, 0, 0));
  EXPECT_NEAR(hits[3].t, hits[0].t / 2, 1e-6f);
  // The geometric normal of an outward-wound sphere points outwards, along the ray.
  EXPECT_GT(dot(hits[0].normal, dir), 0.99f);
}

// A stopping process (the server's drain after SIGTERM) cancels batches in
// flight: each stops with CANCELLED instead of running to its end, and the
// engine answers again once the request is withdrawn.
TEST(QueryEngine, ACancelRequestStopsBatchesWithCancelledAndLeavesTheEngineUsable) {
  const auto scene = pack({"gen:sphere?level=4"}, 100);
  ASSERT_NE(scene, nullptr);
  // A budget far below the scene: the queued path with builds, not a sweep.
  const auto engine = engine_for(*scene, uint64_t{256} << 10);
  const std::vector<Ray> rays = mixed_rays(scene->bounds, 4000, 7);
  std::vector<Hit> want(rays.size());
  ASSERT_TRUE(engine->intersect(rays, want, QueryOptions{}).ok());
  request_cancel();
  for (const bool reorder : {true, false}) {
    QueryOptions options;
    options.reorder = reorder;
    std::vector<Hit> hits(rays.size());
    const Status status = engine->intersect(rays, hits, options);
    std::vector<uint8_t> flags(rays.size());
    const Status occluded = engine->occluded(rays, flags, options);
    EXPECT_EQ(status.code(), StatusCode::kCancelled) << "reorder " << reorder << ": " << status.to_string();
    EXPECT_EQ(occluded.code(), StatusCode::kCancelled)
        << "reorder " << reorder << ": " << occluded.to_string();
  }
  reset_cancel();
  std::vector<Hit> hits(rays.size());
  ASSERT_TRUE(engine->intersect(rays, hits, QueryOptions{}).ok());
  EXPECT_EQ(std::memcmp(hits.data(), want.data(), hits.size() * sizeof(Hit)), 0);
}

TEST(QueryEngine, InvalidRaysAreCountedMissesOrAStrictErrorNamingTheFirst) {
  const auto scene = pack({"gen:sphere?level=2"}, 64);
  auto engine = engine_for(*scene);
  std::vector<Ray> rays(8);
  for (auto& r : rays) {
    r.origin = {0, 0, -5};
    r.direction = {0, 0, 1};
  }
  rays[1].direction = {0, 0, 0};
  rays[2].origin.x = std::numeric_limits<float>::quiet_NaN();
  rays[3].tnear = 3;
  rays[3].tfar = 2;
  rays[4].direction.y = std::numeric_limits<float>::infinity();
  // Finite but beyond Embree's range (it would abort on them): aimed at the
  // sphere, so they would reach a brick.
  rays[6].origin.z = -3e38f;
  rays[7].direction.z = 2e19f;
  QueryStats stats;
  const auto hits = intersect(*engine, rays, {}, &stats);
  EXPECT_EQ(stats.invalid_rays, 6u);
  EXPECT_TRUE(hits[0].is_hit());
  EXPECT_TRUE(hits[5].is_hit());
  for (const int i : {1, 2, 3, 4, 6, 7}) EXPECT_FALSE(hits[i].is_hit()) << i;
  std::vector<uint8_t> occluded(rays.size());
  ASSERT_TRUE(engine->occluded(rays, occluded, {}).ok());
  EXPECT_EQ(occluded, (std::vector<uint8_t>{1, 0, 0, 0, 0, 1, 0, 0}));
  QueryOptions one_by_one;
  one_by_one.reorder = false;
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, one_by_one), hits));
  EXPECT_STREQ(ray_problem(rays[6]), "an origin component is beyond +-1.844e18 (the intersector's range)");
  EXPECT_STREQ(ray_problem(rays[7]), "a direction component is beyond +-1.844e18 (the intersector's range)");
  expect_strict_error(*engine, rays, "ray 1: direction is zero");
}

// A scene of a few bricks, all resident under a budget that holds it: the
// in-cache sweep answers (ray chunks through all their bricks) bitwise as the
// queues do, counts the same visits, nodes, hits and invalid rays, and takes
// each brick from the cache at most once per batch.
TEST(QueryEngine, InCacheSweepAnswersAndCountsExactlyAsTheQueues) {
  const auto scene = pack({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5"}, 1200);
  auto engine = engine_for(*scene);
  ASSERT_GT(engine->store().brick_count(), 1u);
  ASSERT_LE(engine->store().brick_count(), 16u);
  auto rays = mixed_rays(scene->bounds, 5000, 21);  // several 1024-ray chunks
  rays[17].direction = {0, 0, 0};
  rays[3001].origin.y = std::numeric_limits<float>::quiet_NaN();
  QueryOptions queued;
  queued.in_cache_sweep = false;
  QueryStats cold;
  const std::vector<Hit> expected = intersect(*engine, rays, queued, &cold);
  EXPECT_GT(cold.brick_builds, 0u);
  expect_matches_reference(*scene, rays, expected);

  QueryStats queued_stats, sweep_stats;
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, queued, &queued_stats), expected));
  EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, {}, &sweep_stats), expected));
  EXPECT_EQ(sweep_stats.rays_hit, queued_stats.rays_hit);
  EXPECT_EQ(sweep_stats.invalid_rays, 2u);
  EXPECT_EQ(queued_stats.invalid_rays, 2u);
  EXPECT_EQ(sweep_stats.brick_visits, queued_stats.brick_visits);
  EXPECT_EQ(sweep_stats.upper_nodes_visited, queued_stats.upper_nodes_visited);
  EXPECT_EQ(sweep_stats.brick_builds, 0u);
  EXPECT_LE(sweep_stats.brick_acquisitions, engine->store().brick_count());
  EXPECT_GT(queued_stats.brick_acquisitions, engine->store().brick_count())
      << "the queues trace 512-ray chunks";
  EXPECT_EQ(sweep_stats.cache_hits, sweep_stats.brick_acquisitions);

  // Any hit, thread counts, strict mode.
  std::vector<uint8_t> occluded_queued(rays.size()), occluded_swept(rays.size());
  QueryStats any_queued, any_swept;
  ASSERT_TRUE(engine->occluded(rays, occluded_queued, queued, &any_queued).ok());
  ASSERT_TRUE(engine->occluded(rays, occluded_swept, {}, &any_swept).ok());
  EXPECT_EQ(occluded_swept, occluded_queued);
  EXPECT_EQ(any_swept.rays_hit, any_queued.rays_hit);
  EXPECT_EQ(any_swept.brick_visits, any_queued.brick_visits);
  for (const int threads : {1, 2, 4}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    EXPECT_TRUE(bitwise_equal(intersect(*engine, rays), expected)) << threads << " threads";
  }
  expect_strict_error(*engine, rays, "ray 17: direction is zero");

  // Concurrent swept batches: each gets its serial answer.
  std::vector<std::vector<Ray>> batches;
  std::vector<std::vector<Hit>> serial;
  for (int b = 0; b < 4; ++b) {
    batches.push_back(mixed_rays(scene->bounds, 2500, 40 + b));
    serial.push_back(intersect(*engine, batches.back(), queued));
  }
  std::vector<std::vector<Hit>> got(batches.size());
  std::vector<std::thread> threads;
  for (std::size_t b = 0; b < batches.size(); ++b)
    threads.emplace_back([&, b] { got[b] = intersect(*engine, batches[b]); });
  for (auto& t : threads) t.join();
  for (std::size_t b = 0; b < batches.size(); ++b)
    EXPECT_TRUE(bitwise_equal(got[b], serial[b])) << "batch " << b;
}

// The resident bricks' one Embree scene (EmbreeBrickSet) against the upper
// walk brick by brick (the sweep and the queues) and the float64 reference:
// bitwise the same hits and occlusions, ties between duplicated triangles
// across and inside bricks, overlapping bricks, coherent camera rays (streams
// across bricks), rays with negative zeros, short segments and invalid rays,
// at 1 and 2 threads, shuffled, and under a budget that cannot hold the
// scene (no set).
TEST(QueryEngine, ResidentBrickSetAnswersBitwiseAsBrickByBrick) {
  struct Case {
    std::vector<std::string> inputs;
    uint32_t brick_triangles;
  };
  const std::vector<Case> cases = {
      {{"gen:sphere?level=4", "gen:sphere?level=4"}, 1100},
      {{"gen:stadium?size=50&level=4&object=2&segments=4"}, 1500},
      {{"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=1.5"}, 1200},
  };
  // Both structures that offer a set: Embree's instancing scene and the
  // bvh bricks' own (bvh_brick_set.h).
  for (const Case& c : cases)
    for (const char* structure : {"embree", "bvh"}) {
      SCOPED_TRACE(std::string(structure) + " " + c.inputs[0] + " bricks of " +
                   std::to_string(c.brick_triangles));
      const auto scene = pack(c.inputs, c.brick_triangles);
      auto engine = engine_for(*scene, uint64_t{1} << 30, true, structure);
      const uint32_t bricks = engine->store().brick_count();
      ASSERT_GT(bricks, 1u);
      ASSERT_LE(bricks, 16u);
      std::size_t generic = 0;
      std::vector<Ray> rays = mixed_camera_and_in_plane_rays(scene->bounds, 3000, 77, generic);
      rays[5].direction = {0, 0, 0};
      rays[2999].tnear = 2.0f;
      rays[2999].tfar = 1.0f;
      QueryOptions walked;
      walked.brick_set = false;
      QueryOptions queued = walked;
      queued.in_cache_sweep = false;
      QueryOptions in_set;
      in_set.brick_set_min_rays = 0;
      QueryStats cold;
      const std::vector<Hit> expected = intersect(*engine, rays, queued, &cold);
      EXPECT_EQ(cold.brick_builds, bricks) << "every brick resident after the first batch";
      // The in-plane rays graze edges on purpose: many are float/float64 edge
      // ties, so the reference is checked on the others.
      expect_matches_reference(*scene, std::vector<Ray>(rays.begin(), rays.begin() + generic),
                               std::vector<Hit>(expected.begin(), expected.begin() + generic));
      EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, walked), expected)) << "swept";

      QueryStats set_stats;
      EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, in_set, &set_stats), expected)) << "set";
      EXPECT_EQ(set_stats.rays_in_brick_set, rays.size() - 2);
      EXPECT_EQ(set_stats.invalid_rays, 2u);
      EXPECT_EQ(set_stats.brick_visits, 0u);
      EXPECT_EQ(set_stats.brick_builds, 0u);
      EXPECT_EQ(set_stats.brick_acquisitions, bricks);
      EXPECT_EQ(set_stats.cache_hits, bricks);
      uint64_t hit = 0;
      for (const Hit& h : expected) hit += h.is_hit();
      EXPECT_EQ(set_stats.rays_hit, hit);
      EXPECT_GT(hit, rays.size() / 4);
      // The default takes the set only for large batches.
      QueryStats small;
      intersect(*engine, rays, {}, &small);
      EXPECT_EQ(small.rays_in_brick_set, 0u);

      for (const int threads : {1, 2}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        EXPECT_TRUE(bitwise_equal(intersect(*engine, rays, in_set), expected)) << threads << " threads";
      }
      const std::vector<Hit> unshuffled = intersect_shuffled(*engine, rays, in_set, 5);
      EXPECT_TRUE(bitwise_equal(unshuffled, expected)) << "shuffled";

      // Any hit.
      std::vector<uint8_t> occluded_walked(rays.size()), occluded_set(rays.size(), 9);
      QueryStats any_set;
      ASSERT_TRUE(engine->occluded(rays, occluded_walked, queued).ok());
      ASSERT_TRUE(engine->occluded(rays, occluded_set, in_set, &any_set).ok());
      EXPECT_EQ(occluded_set, occluded_walked);
      EXPECT_EQ(any_set.rays_in_brick_set, rays.size() - 2);
      for (std::size_t i = 0; i < rays.size(); ++i)
        EXPECT_EQ(occluded_set[i] != 0, expected[i].is_hit()) << "ray " << i;

      QueryOptions strict = in_set;
      strict.strict = true;
      std::vector<Hit> out(rays.size());
      const Status s = engine->intersect(rays, out, strict);
      EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
      EXPECT_NE(s.message().find("ray 5: direction is zero"), std::string::npos) << s.message();

      // A budget of one brick: never all resident, so no set, same answers.
      auto tight = engine_for(*scene, one_brick_budget(*engine), true, structure);
      QueryStats tight_stats;
      EXPECT_TRUE(bitwise_equal(intersect(*tight, rays, in_set, &tight_stats), expected)) << "one brick";
      EXPECT_EQ(tight_stats.rays_in_brick_set, 0u);
    }
}

TEST(QueryEngine, ConcurrentBatchesShareOneCacheAndEachGetsItsSerialAnswer) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=3)&copies=40"}, 300);
  auto reference = engine_for(*scene);
  std::vector<std::vector<Ray>> batches;
  std::vector<std::vector<Hit>> expected;
  for (int b = 0; b < 6; ++b) {
    batches.push_back(mixed_rays(scene->bounds, 1500, 100 + b));
    expected.push_back(intersect(*reference, batches.back()));
  }
  auto shared = engine_for(*scene, 3 * one_brick_budget(*reference));
  std::vector<std::vector<Hit>> got(batches.size());
  std::vector<std::thread> threads;
  for (std::size_t b = 0; b < batches.size(); ++b) {
    threads.emplace_back([&, b] { got[b] = intersect(*shared, batches[b]); });
  }
  for (auto& t : threads) t.join();
  for (std::size_t b = 0; b < batches.size(); ++b)
    EXPECT_TRUE(bitwise_equal(got[b], expected[b])) << "batch " << b;
  EXPECT_LE(shared->cache().counters().peak_resident_bytes, shared->cache().budget_bytes());
}

uint64_t total_reservation(const QueryEngine& engine) {
  uint64_t total = 0;
  for (const auto& b : engine.store().manifest().bricks)
    total += engine.cache().builder().reserve_bytes(b.triangle_count);
  return total;
}

std::vector<uint8_t> occluded_flags(QueryEngine& engine, const std::vector<Ray>& rays,
                                    QueryOptions options = {}, QueryStats* stats = nullptr) {
  std::vector<uint8_t> flags(rays.size(), 7);
  const Status s = engine.occluded(rays, flags, options, stats);
  EXPECT_TRUE(s.ok()) << s.to_string();
  return flags;
}

// Under a quarter of the scene's size, bricks being built are also traced by
// the rays that reach them later (trace-ahead), in one or several builds at
// once: fewer builds, the same answers bitwise, the same visits.
TEST(QueryEngine, TraceAheadUnderATightBudgetBuildsLessAndAnswersBitwiseTheSame) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=3)&copies=40", "gen:sphere?level=4"}, 300);
  const auto rays = mixed_rays(scene->bounds, 6000, 21);
  // Embree bricks: their reservation is close to their true size, so a
  // quarter of the reservations really forces rebuilds (bvh bricks take a
  // fifth of what they reserve).
  auto unlimited = engine_for(*scene, uint64_t{1} << 30, true, "embree");
  QueryStats unlimited_stats;
  const std::vector<Hit> expected = intersect(*unlimited, rays, {}, &unlimited_stats);
  const std::vector<uint8_t> expected_occluded = occluded_flags(*unlimited, rays);
  EXPECT_EQ(unlimited_stats.rays_traced_ahead, 0u) << "nothing to save when the scene fits";
  const uint64_t quarter = total_reservation(*unlimited) / 4;
  const uint32_t scene_bricks = unlimited->store().brick_count();
  ASSERT_GT(quarter, 2 * one_brick_budget(*unlimited));
  QueryOptions without;
  without.trace_ahead = false;
  for (const bool proxies : {false, true}) {
    for (const int threads : {1, 2, 4}) {
      SCOPED_TRACE(std::string(proxies ? "proxies, " : "") + std::to_string(threads) + " threads");
      // Raised above the machine's cores too: four builds at once.
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      tbb::task_arena arena(threads);
      arena.execute([&] {
        QueryStats on, off, on_any, off_any;
        auto ahead = engine_for(*scene, quarter, proxies, "embree");
        EXPECT_TRUE(bitwise_equal(intersect(*ahead, rays, {}, &on), expected));
        auto plain = engine_for(*scene, quarter, proxies, "embree");
        EXPECT_TRUE(bitwise_equal(intersect(*plain, rays, without, &off), expected));
        EXPECT_GT(on.rays_traced_ahead, 0u);
        EXPECT_EQ(off.rays_traced_ahead, 0u);
        // With proxies these rays rebuild next to nothing either way, and
        // which bricks concurrent builds evict depends on their timing: a
        // build or so per thread either way.
        if (proxies) {
          EXPECT_LE(on.brick_builds, off.brick_builds + static_cast<uint64_t>(threads));
        } else {
          EXPECT_LT(on.brick_builds, off.brick_builds) << scene_bricks << " bricks";
        }
        EXPECT_LE(on.peak_bytes_resident, quarter);
        EXPECT_EQ(on.brick_visits + on.bricks_skipped_by_proxy,
                  off.brick_visits + off.bricks_skipped_by_proxy);
        EXPECT_EQ(occluded_flags(*ahead, rays, {}, &on_any), expected_occluded);
        EXPECT_EQ(occluded_flags(*plain, rays, without, &off_any), expected_occluded);
        EXPECT_GT(on_any.rays_traced_ahead, 0u);
        // The hit count (taken as rays finish) is the count of the answers.
        const auto hit_count = static_cast<uint64_t>(
            std::count_if(expected.begin(), expected.end(), [](const Hit& h) { return h.is_hit(); }));
        const auto occluded_count =
            static_cast<uint64_t>(std::count(expected_occluded.begin(), expected_occluded.end(), 1));
        EXPECT_EQ(on.rays_hit, hit_count);
        EXPECT_EQ(off.rays_hit, hit_count);
        EXPECT_EQ(on_any.rays_hit, occluded_count);
        EXPECT_EQ(off_any.rays_hit, occluded_count);
        // A warm second batch under the same budget.
        EXPECT_TRUE(bitwise_equal(intersect(*ahead, rays), expected));
      });
    }
  }
}

std::unique_ptr<QueryEngine> engine_with_quality(const PackedScene& scene, uint64_t cache_bytes,
                                                 const std::string& quality) {
  EngineOptions options;
  options.cache_bytes = cache_bytes;
  options.brick_accel = "embree";
  if (!quality.empty()) options.accel_options["quality"] = quality;
  auto engine = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  return std::move(engine).value();
}

// The build quality changes no answer of rays in general position; rays
// running in an axis plane along mesh edges may hit the other triangle of an
// edge (Embree culls the boxes whose face such a ray runs along, and which
// boxes those are depends on the tree), never anything farther than the
// other side of that edge.
TEST(QueryEngine, EmbreeBuildQualityChangesAnAnswerOnlyAtAnEdgeInTheRaysAxisPlane) {
  const auto scene = pack({"gen:sphere?level=4", "gen:sphere?level=4", "gen:torus?cx=1.5"}, 400);
  std::size_t generic = 0;
  const std::vector<Ray> rays = mixed_camera_and_in_plane_rays(scene->bounds, 4000, 31, generic);
  auto medium = engine_with_quality(*scene, uint64_t{1} << 30, "medium");
  const std::vector<Hit> expected = intersect(*medium, rays);
  const std::vector<uint8_t> expected_occluded = occluded_flags(*medium, rays);
  for (const std::string quality : {"low", "high"}) {
    SCOPED_TRACE(quality);
    auto engine = engine_with_quality(*scene, uint64_t{1} << 30, quality);
    const std::vector<Hit> got = intersect(*engine, rays);
    for (std::size_t i = 0; i < rays.size(); ++i) {
      if (std::memcmp(&got[i], &expected[i], sizeof(Hit)) == 0) continue;
      EXPECT_GE(i, generic) << "ray " << i << " is in general position";
      EXPECT_EQ(got[i].is_hit(), expected[i].is_hit()) << "ray " << i;
      EXPECT_NEAR(got[i].t, expected[i].t, 1e-5f * std::max(1.0f, expected[i].t)) << "ray " << i;
    }
    EXPECT_EQ(occluded_flags(*engine, rays), expected_occluded);
  }
}

// Under a budget that cannot hold the scene the bricks are built at the
// quality of an unlimited budget, so every answer is bitwise the same,
// those of rays along edges in their axis plane included.
TEST(QueryEngine, ABudgetBelowTheSceneKeepsTheBuildQualityAndEveryAnswer) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=3)&copies=12"}, 300);
  auto roomy = engine_with_quality(*scene, uint64_t{1} << 30, "");
  EXPECT_TRUE(roomy->cache_fits_scene());
  EXPECT_FALSE(roomy->accel_options().contains("quality"));
  const uint64_t tight = total_reservation(*roomy) / 4;
  auto budgeted = engine_with_quality(*scene, tight, "");
  EXPECT_FALSE(budgeted->cache_fits_scene());
  EXPECT_FALSE(budgeted->accel_options().contains("quality"));
  auto chosen = engine_with_quality(*scene, tight, "low");
  EXPECT_EQ(chosen->accel_options().at("quality"), "low");
  std::vector<Ray> rays = mixed_rays(scene->bounds, 3000, 32);
  const std::vector<Ray> in_plane = axis_plane_rays(scene->bounds);
  rays.insert(rays.end(), in_plane.begin(), in_plane.end());
  EXPECT_TRUE(bitwise_equal(intersect(*budgeted, rays), intersect(*roomy, rays)));
}

TEST(QueryEngine, ReorderingLoadsEachBrickFewerTimesThanRayOrder) {
  const auto scene = pack({"gen:city?of=(gen:sphere?level=3)&copies=30"}, 300);
  const auto rays = mixed_rays(scene->bounds, 2000, 7);
  auto probe = engine_for(*scene);
  const uint64_t tiny = 2 * one_brick_budget(*probe);
  QueryStats reordered, in_order;
  // Proxies off: they take the same visits away from both orders, which is
  // not what this measures (core/proxy/proxy_engine_test.cpp covers them).
  auto a = engine_for(*scene, tiny, false);
  intersect(*a, rays, {}, &reordered);
  auto b = engine_for(*scene, tiny, false);
  QueryOptions serial;
  serial.reorder = false;
  intersect(*b, rays, serial, &in_order);
  EXPECT_LT(reordered.brick_builds * 5, in_order.brick_builds)
      << reordered.brick_builds << " vs " << in_order.brick_builds;
  EXPECT_EQ(reordered.brick_visits, in_order.brick_visits);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
