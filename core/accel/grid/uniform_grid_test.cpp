// The uniform grid against brute force with the same triangle test (bitwise:
// the walk may only change which triangles are tested, never the answer), on
// generated scenes, soups, the bunny, rays aimed at a closed mesh's vertices
// and edges from inside at offsets up to 1e6 (0 leaks with the watertight
// test), rays lying in cell boundary planes, running along cell edges and
// passing exactly through cell corners; the walk's order and its stop on a
// hand-made grid; mailboxing (same answers, tests saved); the resolution
// rules and budgets; validate(); the factory; and the serialiser (round
// trip, malformed and fuzzed payloads).
#include "core/accel/grid/uniform_grid.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/grid/grid_brick.h"
#include "core/accel/grid/grid_brick_serializer.h"
#include "core/accel/grid/uniform_grid_builder.h"
#include "core/accel/grid/uniform_grid_traversal.h"
#include "core/accel/kdtree/split_tree_test_util.h"
#include "core/accel/serializer_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::bounds_of;
using accel_test::load_brick_from;
using split_tree_test::brute_force;
using split_tree_test::mixed_rays;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 400;
#else
constexpr std::size_t kRays = 3000;
#endif

UniformGrid build_grid(const BrickData& brick, const UniformGridBuilder::Config& config = {}) {
  const BrickData kept = split_tree_test::usable(brick);
  return UniformGridBuilder::build(kept.triangles, kept.ids, config).tree;
}

struct GridWalks {
  template <class Test>
  static bool closest(const UniformGridView& view, const Ray& ray, Hit& hit) {
    return grid_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const UniformGridView& view, const Ray& ray) {
    return grid_any_hit<Test>(view, ray);
  }
};

void expect_every_test_matches(const std::string& what, const UniformGrid& grid, const std::vector<Ray>& rays,
                               std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<GridWalks>(what, grid, rays, min_hits);
}

TEST(UniformGrid, MatchesBruteForceOnGeneratedScenesSoupsAndTheBunny) {
  split_tree_test::expect_every_test_matches_on_the_usual_scenes<GridWalks>(
      [](const BrickData& brick) { return build_grid(brick); }, kRays);
  const BrickData random = accel_test::random_triangles(1500, 4);
  UniformGridBuilder::Config pbrt;
  pbrt.rule = UniformGridBuilder::ResolutionRule::kPbrt;
  const BrickData torus = load_brick_from("gen:torus?nu=48&nv=24");
  expect_every_test_matches("torus pbrt", build_grid(torus, pbrt), mixed_rays(torus, kRays, 26), kRays / 10);
  UniformGridBuilder::Config fine;
  fine.cells_per_triangle = 16;
  expect_every_test_matches("random fine", build_grid(random, fine), mixed_rays(random, kRays, 27),
                            kRays / 10);
}

TEST(UniformGrid, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    // A fine grid, so that many vertices lie near cell boundaries.
    UniformGridBuilder::Config fine;
    fine.cells_per_triangle = 8;
    const UniformGrid grid = build_grid(sphere, fine);
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, grid, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// Rays in the grid's own boundary planes (parallel to an axis, origin on the
// plane), along cell edges (in two planes at once), and through cell corners
// (diagonals from one corner, crossing three planes at the same t), on a flat
// terrain whose vertices lie on boundaries and on a sphere.
TEST(UniformGrid, RaysAlongCellBoundariesAndThroughCellCornersLoseNothing) {
  for (const char* spec :
       {"gen:terrain?n=16&size=4&height=0", "gen:terrain?n=12&size=4&height=0.7", "gen:sphere?level=3"}) {
    const BrickData brick = load_brick_from(spec);
    UniformGridBuilder::Config config;
    config.cells_per_triangle = 4;
    const UniformGrid grid = build_grid(brick, config);
    const UniformGridView view = grid.view();
    const Aabb b = view.bounds;
    std::vector<Ray> rays;
    const float reach = length(b.extent()) + 1.0f;
    for (int axis = 0; axis < 3; ++axis) {
      for (uint32_t j = 1; j < view.resolution[axis]; ++j) {
        const float plane = view.boundary(axis, j);
        for (int other = 0; other < 3; ++other) {
          if (other == axis) continue;
          for (const float sign : {1.0f, -1.0f}) {
            Ray in_plane;
            in_plane.origin = b.center() + Vec3f(0.013f, -0.021f, 0.017f);
            in_plane.origin[axis] = plane;
            in_plane.origin[other] = sign > 0 ? b.lo[other] - 1.0f : b.hi[other] + 1.0f;
            in_plane.direction = {0, 0, 0};
            in_plane.direction[other] = sign;
            rays.push_back(in_plane);
            // Also tilted within the plane.
            Ray tilted = in_plane;
            tilted.direction[3 - axis - other] = 0.37f * sign;
            rays.push_back(tilted);
          }
        }
      }
    }
    // Along cell edges: in the planes of two axes at once.
    for (uint32_t i = 1; i < view.resolution[0]; ++i) {
      for (uint32_t j = 1; j < view.resolution[1]; j += 2) {
        Ray edge;
        edge.origin = {view.boundary(0, i), view.boundary(1, j), b.hi.z + 1.0f};
        edge.direction = {0, 0, -1};
        rays.push_back(edge);
      }
    }
    // Through corners: from a grid corner point, along directions that reach
    // other corners (whole numbers of cells per axis).
    for (uint32_t i = 1; i < view.resolution[0]; i += 3) {
      for (uint32_t j = 1; j < view.resolution[1]; j += 3) {
        const uint32_t k = view.resolution[2] > 1 ? view.resolution[2] / 2 : 0;
        const Vec3f corner{view.boundary(0, i), view.boundary(1, j),
                           k == 0 ? b.center().z : view.boundary(2, k)};
        for (const Vec3f& cells : {Vec3f(1, 1, 1), Vec3f(-1, 1, -1), Vec3f(2, -1, 1), Vec3f(1, 1, 0)}) {
          Ray diagonal;
          diagonal.origin = corner;
          diagonal.direction = {cells.x * view.cell_width.x, cells.y * view.cell_width.y,
                                cells.z * view.cell_width.z};
          rays.push_back(diagonal);
          Ray back = diagonal;
          back.origin = corner + diagonal.direction * 5.0f;
          back.direction = diagonal.direction * -1.0f;
          rays.push_back(back);
        }
      }
    }
    // Straight down onto every vertex of the scene (vertices of the flat
    // terrain lie on cell boundaries).
    for (std::size_t t = 0; t < brick.triangles.size(); t += 3) {
      Ray down;
      down.origin = brick.triangles[t].v0 + Vec3f(0, 0, reach);
      down.direction = {0, 0, -1};
      rays.push_back(down);
    }
    ASSERT_GT(rays.size(), 20u) << spec;
    expect_every_test_matches(std::string(spec) + " boundaries", grid, rays, 1);
  }
}

// A hand-made 2 x 1 x 1 grid over x in [0, 2.5]: triangle 0 (in the plane
// 2x + y = 4) spans both cells and is hit at t = 2.875, in cell 1; triangle 1
// (x = 1.5) lies only in cell 1 and is hit nearer, at t = 2.5. A ray from
// x = -1 along +x finds triangle 0 in cell 0, beyond that cell's exit, and
// must go on to cell 1, where triangle 1 wins; triangle 0 is not tested
// again there (the mailbox).
TEST(UniformGrid, ASpanningTriangleDoesNotEndTheWalkEarlyAndIsTestedOnce) {
  UniformGrid grid;
  grid.triangles = {Triangle{{0.0f, 4.0f, -1.0f}, {2.5f, -1.0f, -1.0f}, {2.5f, -1.0f, 2.0f}},
                    Triangle{{1.5f, -1.0f, -1.0f}, {1.5f, 2.0f, -1.0f}, {1.5f, -1.0f, 2.0f}}};
  grid.records = {{grid.triangles[0].unit_normal(), 0, 0}, {grid.triangles[1].unit_normal(), 0, 1}};
  for (const Triangle& tri : grid.triangles) grid.bounds.extend(tri.bounds());
  grid.resolution = {2, 1, 1};
  grid.cell_width = {1.25f, 5.0f, 3.0f};
  grid.cell_starts = {0, 1, 3};
  grid.refs = {0, 0, 1};
  ASSERT_TRUE(grid.view().validate().ok());
  Ray ray;
  ray.origin = {-1.0f, 0.25f, 0.25f};
  ray.direction = {1, 0, 0};
  Hit want;
  bool any = false;
  brute_force<WatertightTriangleTest>(grid.view(), ray, want, any);
  ASSERT_TRUE(want.is_hit());
  EXPECT_EQ(want.primitive_id, 1u);
  EXPECT_FLOAT_EQ(want.t, 2.5f);
  Hit got;
  CountingMailbox<TriangleMailbox> counting;
  EXPECT_TRUE(grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, got, counting));
  EXPECT_EQ(std::memcmp(&want, &got, sizeof(Hit)), 0);
  EXPECT_EQ(counting.references, 3u);
  EXPECT_EQ(counting.saved, 1u);
  // From the other side the ray meets triangle 0 first (x = 1.875, t =
  // 1.625) inside cell 1 and stops there, never visiting cell 0.
  Ray back;
  back.origin = {3.5f, 0.25f, 0.25f};
  back.direction = {-1, 0, 0};
  CountingMailbox<TriangleMailbox> back_counting;
  Hit back_hit;
  EXPECT_TRUE(grid_closest_hit<WatertightTriangleTest>(grid.view(), back, back_hit, back_counting));
  EXPECT_EQ(back_hit.primitive_id, 0u);
  EXPECT_FLOAT_EQ(back_hit.t, 1.625f);
  EXPECT_EQ(back_counting.references, 2u) << "cell 0 is never visited";
}

TEST(UniformGrid, MailboxingSavesTestsAndChangesNoAnswer) {
  // Cells smaller than the triangles: each spans several.
  const BrickData torus = load_brick_from("gen:torus?nu=48&nv=24");
  UniformGridBuilder::Config fine;
  fine.cells_per_triangle = 16;
  const UniformGrid grid = build_grid(torus, fine);
  EXPECT_GT(grid.refs.size(), 2 * grid.triangles.size());
  const auto rays = mixed_rays(torus, kRays, 41);
  uint64_t references = 0, saved = 0;
  for (const Ray& ray : rays) {
    Hit with, without;
    CountingMailbox<TriangleMailbox> counting;
    grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, with, counting);
    grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, without, NoMailbox{});
    EXPECT_EQ(std::memcmp(&with, &without, sizeof(Hit)), 0);
    references += counting.references;
    saved += counting.saved;
  }
  EXPECT_GT(saved, references / 10) << saved << " of " << references;
}

// Not part of the suite (docs/BENCHMARKS.md, "Grids"): the references a
// walk reaches and the triangle tests the mailbox saves, per ray, and the
// time with and without it, at the default resolution and a fine one.
// build/tests/outcore_tests --gtest_also_run_disabled_tests
//   --gtest_filter='*MeasureMailboxing'
TEST(UniformGrid, DISABLED_MeasureMailboxing) {
  for (const std::string& spec : {accel_test::bunny_path(), std::string("gen:terrain?n=200&size=20&height=1"),
                                  std::string("gen:stadium?level=5")}) {
    const BrickData brick = load_brick_from(spec);
    const auto rays = mixed_rays(brick, 200000, 77);
    for (const float lambda : {2.0f, 8.0f}) {
      UniformGridBuilder::Config config;
      config.cells_per_triangle = lambda;
      const UniformGrid grid = build_grid(brick, config);
      CountingMailbox<TriangleMailbox> counting;
      const auto t0 = std::chrono::steady_clock::now();
      for (const Ray& ray : rays) {
        Hit hit;
        grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, hit, counting);
      }
      const auto t1 = std::chrono::steady_clock::now();
      for (const Ray& ray : rays) {
        Hit hit;
        grid_closest_hit<WatertightTriangleTest>(grid.view(), ray, hit, NoMailbox{});
      }
      const auto t2 = std::chrono::steady_clock::now();
      const double n = static_cast<double>(rays.size());
      std::printf(
          "%s lambda %.0f: %u x %u x %u cells, %.2f refs/triangle; per ray %.1f references, %.1f tests "
          "saved (%.0f %%); %.3f s with the mailbox, %.3f s without\n",
          spec.c_str(), lambda, grid.resolution[0], grid.resolution[1], grid.resolution[2],
          static_cast<double>(grid.refs.size()) / static_cast<double>(grid.triangles.size()),
          static_cast<double>(counting.references) / n, static_cast<double>(counting.saved) / n,
          100.0 * static_cast<double>(counting.saved) / static_cast<double>(counting.references),
          std::chrono::duration<double>(t1 - t0).count(), std::chrono::duration<double>(t2 - t1).count());
    }
  }
}

TEST(GridLattice, CellsHoldingACoordinateDoNotDependOnTheGuess) {
  // The filing guesses by a product, the lattice by a quotient: any guess
  // must settle on the same cells, boundaries and bounds included.
  const GridLattice lattice =
      GridLattice::over({{-3.1f, 0.0f, 1e6f}, {7.7f, 1e-3f, 1e6f + 64.0f}}, {37, 5, 11});
  std::mt19937 rng(21);
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<float> xs = {lattice.bounds.lo[axis], lattice.bounds.hi[axis]};
    for (uint32_t j = 1; j < lattice.resolution[axis]; ++j) {
      const float b = lattice.boundary(axis, j);
      xs.insert(xs.end(), {b, std::nextafter(b, -INFINITY), std::nextafter(b, INFINITY)});
    }
    std::uniform_real_distribution<float> inside(lattice.bounds.lo[axis], lattice.bounds.hi[axis]);
    for (int k = 0; k < 50; ++k) xs.push_back(inside(rng));
    for (const float x : xs) {
      const uint32_t lowest = lattice.lowest_cell_holding(axis, x);
      const uint32_t highest = lattice.highest_cell_holding(axis, x);
      EXPECT_LE(lowest, highest);
      EXPECT_LE(lattice.cell_lo(axis, lowest), x);
      EXPECT_GE(lattice.cell_hi(axis, highest), x);
      for (uint32_t guess = 0; guess < lattice.resolution[axis]; ++guess) {
        ASSERT_EQ(lattice.lowest_cell_holding_from(axis, x, guess), lowest)
            << axis << " " << x << " " << guess;
        ASSERT_EQ(lattice.highest_cell_holding_from(axis, x, guess), highest)
            << axis << " " << x << " " << guess;
      }
    }
  }
}

TEST(UniformGrid, ResolutionFollowsTheRuleAndTheBudgets) {
  Aabb cube;
  cube.extend(Vec3f(0, 0, 0));
  cube.extend(Vec3f(1, 2, 4));
  UniformGridBuilder::Config density;
  density.cells_per_triangle = 2;
  const auto r = UniformGridBuilder::resolution_for(cube, 4000, density);
  const double cells = static_cast<double>(r[0]) * r[1] * r[2];
  EXPECT_GT(cells, 0.5 * 8000);
  EXPECT_LT(cells, 2.0 * 8000);
  EXPECT_LT(r[0], r[1]);
  EXPECT_LT(r[1], r[2]);  // shaped like the box
  // A flat box: one cell across its thickness, the cells shared by the rest.
  Aabb flat;
  flat.extend(Vec3f(0, 0, 0));
  flat.extend(Vec3f(10, 10, 0));
  const auto f = UniformGridBuilder::resolution_for(flat, 5000, density);
  EXPECT_EQ(f[2], 1u);
  EXPECT_NEAR(static_cast<double>(f[0]) * f[1], 10000.0, 2000.0);
  UniformGridBuilder::Config pbrt;
  pbrt.rule = UniformGridBuilder::ResolutionRule::kPbrt;
  const auto p = UniformGridBuilder::resolution_for(cube, 8000, pbrt);
  EXPECT_EQ(p[2], 60u);  // 3 * cbrt(8000) along the longest axis
  EXPECT_EQ(p[0], 15u);
  // The caps.
  pbrt.max_resolution = 32;
  EXPECT_EQ(UniformGridBuilder::resolution_for(cube, 8000, pbrt)[2], 32u);
  // Triangles as large as the grid: references stay within the budget (the
  // grid is coarsened) and every triangle is still found.
  const BrickData huge = accel_test::random_triangles(300, 2);
  UniformGridBuilder::Config finest;
  finest.cells_per_triangle = 16;
  const UniformGrid grid = build_grid(huge, finest);
  EXPECT_LE(grid.refs.size(), UniformGridBuilder::kMaxReferencesPerTriangle * 300 + 64);
  EXPECT_LE(grid.memory_bytes(), UniformGridBuilder::tree_bytes_bound(300));
  std::set<uint32_t> referenced(grid.refs.begin(), grid.refs.end());
  EXPECT_EQ(referenced.size(), grid.triangles.size());
}

TEST(UniformGrid, AViewThatDoesNotHoldTogetherIsAnError) {
  const UniformGrid good = build_grid(load_brick_from("gen:sphere?level=2"));
  ASSERT_TRUE(good.view().validate().ok());
  auto expect_bad = [](UniformGrid grid, const std::string& what) {
    EXPECT_FALSE(grid.view().validate().ok()) << what;
  };
  UniformGrid g = good;
  g.refs[3] = static_cast<uint32_t>(g.triangles.size());
  expect_bad(g, "a reference past the triangles");
  g = good;
  g.cell_starts.pop_back();
  expect_bad(g, "a cell start missing");
  g = good;
  g.resolution[1] += 1;
  expect_bad(g, "resolution not matching the cells");
  g = good;
  g.cell_starts[1] = g.cell_starts[2] + 1;
  expect_bad(g, "a cell ending before it starts");
  g = good;
  g.cell_width.x = std::nanf("");
  expect_bad(g, "a NaN cell width");
  g = good;
  g.cell_starts.clear();
  expect_bad(g, "triangles without cells");
}

TEST(UniformGrid, TheFactoryMakesItByNameAndRejectsBadOptions) {
  const BrickData sphere = load_brick_from("gen:sphere?level=3");
  split_tree_test::expect_the_factory_makes("grid",
                                            {{"triangle_test", "double"},
                                             {"resolution", "pbrt"},
                                             {"cells_per_triangle", "3.5"},
                                             {"max_resolution", "64"}},
                                            {{{"triangle_test", "exact"}},
                                             {{"resolution", "cubic"}},
                                             {{"cells_per_triangle", "0"}},
                                             {{"cells_per_triangle", "17"}},
                                             {{"max_resolution", "5000"}},
                                             {{"max_depth", "8"}}},
                                            sphere, build_grid(sphere), 50);
}

// The serialiser.

GridBrickConfig config_with(TriangleTest test) {
  GridBrickConfig config;
  config.triangle_test = test;
  return config;
}

std::unique_ptr<GridBrickAccel> build_brick(BrickData brick, const GridBrickConfig& config) {
  auto accel = GridBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return std::move(accel).value();
}

using serializer_test::save;
using serializer_test::unowned;

TEST(GridBrickSerializer, RoundTripAnswersBitwiseAndKeepsMemoryAndCounts) {
  for (const TriangleTest test : kAllTriangleTests) {
    for (const std::string& spec : {std::string("gen:sphere?level=3"), accel_test::bunny_path()}) {
      const BrickData brick = load_brick_from(spec);
      const GridBrickSerializer serializer(config_with(test));
      const auto built = build_brick(brick, config_with(test));
      const std::string payload = save(serializer, *built);
      auto loaded = serializer.load(unowned(payload), 7, built->triangle_count());
      ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
      EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes()) << spec;
      EXPECT_EQ((*loaded)->triangle_count(), built->triangle_count());
      serializer_test::expect_same_answers(*built, **loaded, mixed_rays(brick, 1500, 5), spec);
    }
  }
  // An empty brick.
  const GridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto empty = build_brick(BrickData{}, config_with(TriangleTest::kWatertight));
  auto loaded = serializer.load(unowned(save(serializer, *empty)), 1, 0);
  ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
}

TEST(GridBrickSerializer, MalformedPayloadsAreErrorsNamingTheBrick) {
  const BrickData brick = load_brick_from("gen:sphere?level=2");
  const GridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto built = build_brick(brick, config_with(TriangleTest::kWatertight));
  const std::string payload = save(serializer, *built);
  const uint32_t n = built->triangle_count();
  const auto expect_error = [&](std::string_view bytes, uint32_t triangles, const std::string& what) {
    auto loaded = serializer.load(unowned(bytes), 42, triangles);
    ASSERT_FALSE(loaded.ok()) << what;
    EXPECT_EQ(loaded.status().code(), StatusCode::kInvalidArgument) << what;
    EXPECT_NE(loaded.status().message().find("brick 42"), std::string::npos) << loaded.status().message();
  };
  for (const std::size_t cut : {std::size_t{0}, std::size_t{1}, std::size_t{40}, std::size_t{96},
                                payload.size() / 2, payload.size() - 1}) {
    expect_error(std::string_view(payload).substr(0, cut), n, "cut at " + std::to_string(cut));
  }
  expect_error(payload + "x", n, "trailing bytes");
  expect_error(payload, n / 2, "more triangles than the brick has");
  for (const std::size_t field : {8, 16, 24}) {
    std::string huge = payload;
    const uint64_t claimed = uint64_t{1} << 40;
    std::memcpy(huge.data() + field, &claimed, sizeof(claimed));
    expect_error(huge, n, "a count beyond the bytes at offset " + std::to_string(field));
  }
  std::string resolution = payload;
  const uint32_t other = 3;
  std::memcpy(resolution.data() + 36, &other, sizeof(other));
  expect_error(resolution, n, "a resolution that does not make the cells");
  std::string nan_bounds = payload;
  const float nan = std::nanf("");
  std::memcpy(nan_bounds.data() + 48, &nan, sizeof(nan));
  expect_error(nan_bounds, n, "NaN bounds");
  std::string backwards = payload;
  const uint32_t big = 1000000;
  std::memcpy(backwards.data() + 96 + 4, &big, sizeof(big));
  expect_error(backwards, n, "a cell start beyond the references");
  const GridBrickSerializer mt(config_with(TriangleTest::kMt));
  const std::string mt_payload = save(mt, *build_brick(brick, config_with(TriangleTest::kMt)));
  auto wrong = serializer.load(unowned(mt_payload), 0, n);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("triangle test"), std::string::npos) << wrong.status().message();
  std::ostringstream out;
  EXPECT_FALSE(serializer.save(*build_brick(brick, config_with(TriangleTest::kMt)), out).ok());
  auto bvh = make_brick_builder("bvh", {});
  ASSERT_TRUE(bvh.ok());
  auto bvh_brick = (*bvh)->build(BrickData(brick));
  ASSERT_TRUE(bvh_brick.ok());
  EXPECT_FALSE(serializer.save(**bvh_brick, out).ok());
}

TEST(GridBrickSerializer, FuzzedPayloadsNeverCrash) {
  const BrickData brick = load_brick_from("gen:torus?nu=24&nv=12");
  const GridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto built = build_brick(brick, config_with(TriangleTest::kWatertight));
  const std::string payload = save(serializer, *built);
  // The header and the first cell starts, where damage matters most.
  const auto outcome = serializer_test::fuzz(serializer, payload, built->triangle_count(),
                                             mixed_rays(brick, 800, 3), 96 + 4 * 64);
  EXPECT_GT(outcome.refused, 0u);
  EXPECT_GT(outcome.loaded, 0u);
}

TEST(GridBrickSerializer, StructureKeysDifferExactlyWhenTheConfigDoes) {
  std::set<std::string> keys;
  for (const TriangleTest test : kAllTriangleTests)
    keys.insert(GridBrickSerializer(config_with(test)).structure_key());
  GridBrickConfig c;
  c.builder.cells_per_triangle = std::nextafter(2.0f, 3.0f);
  keys.insert(GridBrickSerializer(c).structure_key());
  c = GridBrickConfig{};
  c.builder.rule = UniformGridBuilder::ResolutionRule::kPbrt;
  keys.insert(GridBrickSerializer(c).structure_key());
  c = GridBrickConfig{};
  c.builder.max_resolution = 100;
  keys.insert(GridBrickSerializer(c).structure_key());
  EXPECT_EQ(keys.size(), 6u);
  EXPECT_EQ(GridBrickSerializer(GridBrickConfig{}).structure_key().rfind("grid/", 0), 0u);
  auto made = make_brick_builder("grid", {{"triangle_test", "mt"}});
  ASSERT_TRUE(made.ok());
  ASSERT_NE((*made)->serializer(), nullptr);
  EXPECT_NE((*made)->serializer()->structure_key().find("triangle_test=mt"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
