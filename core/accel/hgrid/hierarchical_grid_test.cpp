// The hierarchical grid against brute force with the same triangle test
// (bitwise: the walk may only change which triangles are tested, never the
// answer), on generated scenes, soups, the bunny and the teapot in a
// stadium; rays aimed at a closed mesh's vertices and edges from inside at
// offsets up to 1e6 (0 leaks with the watertight test); rays along both
// levels' cell boundaries, along the faces of the top cells' clipped boxes
// and through corners; the teapot's top cell getting fine cells that hug
// it; the build's budgets; validate(); the factory; the serialiser's round
// trip, malformed and fuzzed payloads, and structure keys.
#include "core/accel/hgrid/hierarchical_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/hgrid/hgrid_brick.h"
#include "core/accel/hgrid/hgrid_brick_serializer.h"
#include "core/accel/hgrid/hierarchical_grid_builder.h"
#include "core/accel/hgrid/hierarchical_grid_traversal.h"
#include "core/accel/kdtree/split_tree_test_util.h"
#include "core/accel/serializer_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::load_brick_from;
using split_tree_test::brute_force;
using split_tree_test::mixed_rays;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 400;
#else
constexpr std::size_t kRays = 3000;
#endif

HierarchicalGrid build_grid(const BrickData& brick, const HierarchicalGridBuilder::Config& config = {}) {
  const BrickData kept = split_tree_test::usable(brick);
  return HierarchicalGridBuilder::build(kept.triangles, kept.ids, config).tree;
}

struct HgridWalks {
  template <class Test>
  static bool closest(const HierarchicalGridView& view, const Ray& ray, Hit& hit) {
    return hgrid_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const HierarchicalGridView& view, const Ray& ray) {
    return hgrid_any_hit<Test>(view, ray);
  }
};

void expect_every_test_matches(const std::string& what, const HierarchicalGrid& grid,
                               const std::vector<Ray>& rays, std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<HgridWalks>(what, grid, rays, min_hits);
}

// Top cells of about four triangles, so that small scenes have many.
HierarchicalGridBuilder::Config fine_top() {
  HierarchicalGridBuilder::Config config;
  config.top_cells_per_triangle = 0.25f;
  return config;
}

TEST(HierarchicalGrid, MatchesBruteForceOnGeneratedScenesSoupsTheBunnyAndTheTeapotInAStadium) {
  split_tree_test::expect_every_test_matches_on_the_usual_scenes<HgridWalks>(
      [](const BrickData& brick) { return build_grid(brick); }, kRays);
  const BrickData torus = load_brick_from("gen:torus?nu=48&nv=24");
  expect_every_test_matches("torus, fine top", build_grid(torus, fine_top()), mixed_rays(torus, kRays, 20),
                            kRays / 10);
  const BrickData stadium = load_brick_from("gen:stadium?level=4");
  const HierarchicalGrid grid = build_grid(stadium);
  // Rays at the teapot from all around, and rays across the stadium.
  std::vector<Ray> rays = accel_test::rays_from_outside(
      accel_test::bounds_of(load_brick_from("gen:sphere?level=1")), kRays / 2, 3);
  for (Ray& ray : rays) ray.origin = ray.origin + Vec3f(0, 1.5f, 0);
  const auto across = mixed_rays(stadium, kRays / 2, 4);
  rays.insert(rays.end(), across.begin(), across.end());
  expect_every_test_matches("teapot in a stadium", grid, rays, kRays / 10);
}

TEST(HierarchicalGrid, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    const HierarchicalGrid grid = build_grid(sphere, fine_top());
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, grid, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !hgrid_closest_hit<WatertightTriangleTest>(grid.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// Rays in the planes of a lattice's boundaries and faces (parallel to an
// axis and tilted within the plane), and through its corners along
// directions that reach other corners.
void add_lattice_rays(const GridLattice& lattice, const Aabb& scene, std::vector<Ray>& rays) {
  const Aabb& b = lattice.bounds;
  for (int axis = 0; axis < 3; ++axis) {
    for (uint32_t j = 0; j <= lattice.resolution[axis]; ++j) {
      const float plane = j == 0                          ? b.lo[axis]
                          : j == lattice.resolution[axis] ? b.hi[axis]
                                                          : lattice.boundary(axis, j);
      const int other = (axis + 1) % 3;
      Ray in_plane;
      in_plane.origin = b.center() + Vec3f(0.013f, -0.021f, 0.017f) * length(b.extent());
      in_plane.origin[axis] = plane;
      in_plane.origin[other] = scene.lo[other] - 1.0f;
      in_plane.direction = {0, 0, 0};
      in_plane.direction[other] = 1.0f;
      rays.push_back(in_plane);
      Ray tilted = in_plane;
      tilted.direction[3 - axis - other] = 0.37f;
      rays.push_back(tilted);
    }
  }
  for (const Vec3f& cells : {Vec3f(1, 1, 1), Vec3f(-1, 1, -1), Vec3f(2, -1, 1), Vec3f(1, 1, 0)}) {
    Ray diagonal;
    diagonal.origin = b.lo;
    diagonal.direction = {cells.x * lattice.cell_width.x, cells.y * lattice.cell_width.y,
                          cells.z * lattice.cell_width.z};
    if (!(length(diagonal.direction) > 0)) continue;
    rays.push_back(diagonal);
    Ray back = diagonal;
    back.origin = b.hi;
    back.direction = diagonal.direction * -1.0f;
    rays.push_back(back);
  }
}

TEST(HierarchicalGrid, RaysAlongBothLevelsBoundariesClippedBoxesAndCornersLoseNothing) {
  for (const char* spec : {"gen:terrain?n=16&size=4&height=0", "gen:terrain?n=12&size=4&height=0.7",
                           "gen:sphere?level=3", "gen:stadium?level=2&size=20"}) {
    const BrickData brick = load_brick_from(spec);
    const HierarchicalGrid grid = build_grid(brick, fine_top());
    const HierarchicalGridView view = grid.view();
    const Aabb scene = view.grids[0].box;
    std::vector<Ray> rays;
    for (const HgridGrid& g : view.grids) add_lattice_rays(g.lattice(), scene, rays);
    for (std::size_t t = 0; t < brick.triangles.size(); t += 3) {
      Ray down;  // onto vertices, which lie on boundaries of the flat terrain
      down.origin = brick.triangles[t].v0 + Vec3f(0, length(scene.extent()) + 1.0f, 0);
      down.direction = {0, -1, 0};
      rays.push_back(down);
    }
    ASSERT_GT(rays.size(), 40u) << spec;
    EXPECT_GT(view.grids.size(), 1u) << spec;
    // The exact tests only: Möller-Trumbore in float reports hits up to a
    // few ulps outside a triangle, and a ray parallel to a nested grid's
    // face, which lies exactly at its triangles' extent, may get such a hit
    // from brute force that no structure culling by boxes (the bvh's
    // included) reaches. MT is compared on every other test's rays.
    const std::string what = std::string(spec) + " boundaries";
    split_tree_test::expect_matches_brute_force<WatertightTriangleTest, HgridWalks>(what, grid, rays, 1);
    split_tree_test::expect_matches_brute_force<DoubleTriangleTest, HgridWalks>(what, grid, rays, 1);
  }
}

bool overlaps(const Aabb& a, const Aabb& b) {
  return a.lo.x <= b.hi.x && b.lo.x <= a.hi.x && a.lo.y <= b.hi.y && b.lo.y <= a.hi.y && a.lo.z <= b.hi.z &&
         b.lo.z <= a.hi.z;
}

// The teapot in a stadium: the root grid is coarse (a cell per 16
// triangles over the whole stadium, so the teapot shares a cell with the
// floor's large triangles), yet no cell where the teapot is holds more than
// a few dozen triangles, because grids nest where it is dense and each
// hugs its triangles; the uniform grid at the same density leaves
// thousands in a cell there.
TEST(HierarchicalGrid, TheTeapotGetsNestedGridsWhoseCellsHugIt) {
  const BrickData stadium = load_brick_from("gen:stadium?level=5");
  const HierarchicalGrid grid = build_grid(stadium);
  const Aabb teapot{{-1, 0.5f, -1}, {1, 2.5f, 1}};
  EXPECT_GT(grid.grids[0].lattice().cell_width.x, 50.0f);  // the root grid is coarse
  uint32_t most_in_a_cell = 0;
  bool hugging_grid = false;
  for (const HgridGrid& g : grid.grids) {
    if (!overlaps(g.box, teapot)) continue;
    const Vec3f extent = g.box.extent();
    hugging_grid |= std::max({extent.x, extent.y, extent.z}) <= 2.5f;
    const GridLattice lattice = g.lattice();
    for (uint32_t z = 0, c = 0; z < lattice.resolution[2]; ++z) {
      for (uint32_t y = 0; y < lattice.resolution[1]; ++y) {
        for (uint32_t x = 0; x < lattice.resolution[0]; ++x, ++c) {
          const HgridCell& cell = grid.cells[g.first_cell + c];
          if (!cell.is_nested() && overlaps(lattice.cell_box(x, y, z), teapot)) {
            most_in_a_cell = std::max(most_in_a_cell, cell.count());
          }
        }
      }
    }
  }
  EXPECT_TRUE(hugging_grid);
  EXPECT_LE(most_in_a_cell, 48u);
}

TEST(HierarchicalGrid, TheBuildReferencesEveryTriangleAndKeepsItsBudgets) {
  for (const std::string& spec : {accel_test::bunny_path(), std::string("gen:stadium?level=5")}) {
    const BrickData brick = split_tree_test::usable(load_brick_from(spec));
    const auto n = brick.triangles.size();
    const auto built = HierarchicalGridBuilder::build(brick.triangles, brick.ids, {});
    const HierarchicalGrid& grid = built.tree;
    ASSERT_TRUE(grid.view().validate().ok()) << spec;
    EXPECT_EQ(std::set<uint32_t>(grid.refs.begin(), grid.refs.end()).size(), n) << spec;
    EXPECT_LE(grid.grids.size(), HierarchicalGridBuilder::grids_cap(n));
    EXPECT_LE(grid.cells.size(), HierarchicalGridBuilder::cells_cap(n));
    EXPECT_LE(grid.refs.size(), HierarchicalGridBuilder::references_cap(n));
    EXPECT_LE(grid.memory_bytes(), HierarchicalGridBuilder::tree_bytes_bound(n));
    EXPECT_LE(built.peak_bytes, HierarchicalGridBuilder::peak_bytes_bound(n));
    EXPECT_GT(built.peak_bytes, 0u);
  }
  // Large overlapping triangles at the densest setting: the budgets coarsen
  // the cells' grids, and the grid still answers right.
  const BrickData big = accel_test::random_triangles(300, 5);
  HierarchicalGridBuilder::Config dense;
  dense.top_cells_per_triangle = 1.0f;
  dense.cells_per_triangle = 8.0f;
  dense.max_cell_triangles = 1;
  dense.max_levels = kMaxHgridLevels;
  const HierarchicalGrid grid = build_grid(big, dense);
  ASSERT_TRUE(grid.view().validate().ok());
  EXPECT_LE(grid.refs.size(), HierarchicalGridBuilder::references_cap(300));
  expect_every_test_matches("large triangles, dense", grid, mixed_rays(big, 800, 9), 50);
}

TEST(HierarchicalGrid, AViewThatDoesNotHoldTogetherIsAnError) {
  const HierarchicalGrid grid = build_grid(load_brick_from("gen:sphere?level=3"), fine_top());
  ASSERT_TRUE(grid.view().validate().ok());
  ASSERT_GT(grid.grids.size(), 2u);
  std::size_t nesting = 0;  // a cell of the root that nests a grid
  while (!grid.cells[nesting].is_nested()) ++nesting;
  std::size_t run = 0;  // a cell with references
  while (grid.cells[run].is_nested() || grid.cells[run].count() == 0) ++run;
  auto expect_invalid = [](const HierarchicalGrid& bad, const std::string& what) {
    const Status status = bad.view().validate();
    EXPECT_FALSE(status.ok()) << what;
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << what;
  };
  HierarchicalGrid bad = grid;
  bad.grids.pop_back();
  expect_invalid(bad, "a grid missing");
  bad = grid;
  bad.grids[1].first_cell += 1;
  expect_invalid(bad, "cells that do not follow on");
  bad = grid;
  bad.grids[1].resolution[1] = 0;
  expect_invalid(bad, "a resolution of zero");
  bad = grid;
  bad.grids[1].box.hi.x = std::numeric_limits<float>::quiet_NaN();
  expect_invalid(bad, "a NaN box");
  bad = grid;
  bad.cells.pop_back();
  expect_invalid(bad, "a cell missing");
  bad = grid;
  bad.cells[nesting] = HgridCell::nested(0);
  expect_invalid(bad, "the root nested in itself");
  bad = grid;
  bad.cells[nesting] = HgridCell::nested(static_cast<uint32_t>(grid.grids.size()));
  expect_invalid(bad, "a nested grid past the end");
  bad = grid;
  bad.cells[run] = HgridCell::nested(grid.cells[nesting].grid());
  expect_invalid(bad, "a grid nested twice");
  bad = grid;
  bad.cells[nesting] = HgridCell::references(0, 1);
  expect_invalid(bad, "a grid in no cell");
  bad = grid;
  bad.cells[run] = HgridCell::references(static_cast<uint32_t>(grid.refs.size()), 1);
  expect_invalid(bad, "references past the end");
  bad = grid;
  bad.refs[0] = static_cast<uint32_t>(grid.triangles.size());
  expect_invalid(bad, "a reference past the triangles");
}

TEST(HierarchicalGrid, TheFactoryMakesItByNameAndRejectsBadOptions) {
  const BrickData stadium = load_brick_from("gen:stadium?level=3");
  split_tree_test::expect_the_factory_makes("hgrid",
                                            {{"triangle_test", "double"},
                                             {"top_cells_per_triangle", "0.5"},
                                             {"cells_per_triangle", "4"},
                                             {"max_cell_triangles", "16"},
                                             {"max_levels", "4"}},
                                            {{{"triangle_test", "exact"}},
                                             {{"top_cells_per_triangle", "0"}},
                                             {{"top_cells_per_triangle", "2"}},
                                             {{"cells_per_triangle", "9"}},
                                             {{"max_levels", "0"}},
                                             {{"max_levels", "5"}},
                                             {{"max_cell_triangles", "0"}},
                                             {{"cells_per_triangle", "nan"}},
                                             {{"max_depth", "4"}}},
                                            stadium, build_grid(stadium), 50);
}

HgridBrickConfig config_with(TriangleTest test) {
  HgridBrickConfig config;
  config.triangle_test = test;
  return config;
}

std::unique_ptr<HgridBrickAccel> build_brick(BrickData brick, const HgridBrickConfig& config) {
  auto accel = HgridBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return std::move(accel).value();
}

TEST(HgridBrickSerializer, RoundTripAnswersBitwiseAndKeepsMemoryAndCounts) {
  for (const TriangleTest test : kAllTriangleTests) {
    for (const std::string& spec : {std::string("gen:stadium?level=3"), accel_test::bunny_path()}) {
      const BrickData brick = load_brick_from(spec);
      const HgridBrickSerializer serializer(config_with(test));
      const auto built = build_brick(brick, config_with(test));
      const std::string payload = serializer_test::save(serializer, *built);
      auto loaded = serializer.load(serializer_test::unowned(payload), 7, built->triangle_count());
      ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
      EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes()) << spec;
      EXPECT_EQ((*loaded)->triangle_count(), built->triangle_count());
      serializer_test::expect_same_answers(*built, **loaded, mixed_rays(brick, 1500, 5), spec);
    }
  }
  const HgridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto empty = build_brick(BrickData{}, config_with(TriangleTest::kWatertight));
  auto loaded = serializer.load(serializer_test::unowned(serializer_test::save(serializer, *empty)), 1, 0);
  ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
}

TEST(HgridBrickSerializer, MalformedPayloadsAreErrorsNamingTheBrick) {
  const BrickData brick = load_brick_from("gen:sphere?level=2");
  const HgridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto built = build_brick(brick, config_with(TriangleTest::kWatertight));
  const std::string payload = serializer_test::save(serializer, *built);
  const uint32_t n = built->triangle_count();
  const auto expect_error = [&](std::string_view bytes, uint32_t triangles, const std::string& what) {
    auto loaded = serializer.load(serializer_test::unowned(bytes), 42, triangles);
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
  for (const std::size_t field : {8, 16, 24, 32}) {  // the four counts
    std::string huge = payload;
    const uint64_t claimed = uint64_t{1} << 40;
    std::memcpy(huge.data() + field, &claimed, sizeof(claimed));
    expect_error(huge, n, "a count beyond the bytes at offset " + std::to_string(field));
  }
  std::string resolution = payload;
  const uint16_t zero = 0;
  std::memcpy(resolution.data() + 64 + 28, &zero, sizeof(zero));
  expect_error(resolution, n, "a root resolution of zero");
  std::string nan_box = payload;
  const float nan = std::nanf("");
  std::memcpy(nan_box.data() + 64, &nan, sizeof(nan));
  expect_error(nan_box, n, "a NaN box");
  const HgridBrickSerializer mt(config_with(TriangleTest::kMt));
  const std::string mt_payload =
      serializer_test::save(mt, *build_brick(brick, config_with(TriangleTest::kMt)));
  auto wrong = serializer.load(serializer_test::unowned(mt_payload), 0, n);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("triangle test"), std::string::npos) << wrong.status().message();
  std::ostringstream out;
  EXPECT_FALSE(serializer.save(*build_brick(brick, config_with(TriangleTest::kMt)), out).ok());
}

TEST(HgridBrickSerializer, FuzzedPayloadsNeverCrash) {
  const BrickData brick = load_brick_from("gen:torus?nu=24&nv=12");
  const HgridBrickSerializer serializer(config_with(TriangleTest::kWatertight));
  const auto built = build_brick(brick, config_with(TriangleTest::kWatertight));
  const std::string payload = serializer_test::save(serializer, *built);
  // The header, the grids and the first cells.
  const std::size_t front = 64 + sizeof(HgridGrid) * built->view().grids.size() + 8 * 64;
  const auto outcome =
      serializer_test::fuzz(serializer, payload, built->triangle_count(), mixed_rays(brick, 800, 3), front);
  EXPECT_GT(outcome.refused, 0u);
  EXPECT_GT(outcome.loaded, 0u);
}

TEST(HgridBrickSerializer, StructureKeysDifferExactlyWhenTheConfigDoes) {
  std::set<std::string> keys;
  for (const TriangleTest test : kAllTriangleTests)
    keys.insert(HgridBrickSerializer(config_with(test)).structure_key());
  HgridBrickConfig c;
  c.builder.cells_per_triangle = std::nextafter(2.0f, 3.0f);
  keys.insert(HgridBrickSerializer(c).structure_key());
  c = HgridBrickConfig{};
  c.builder.top_cells_per_triangle = 0.125f;
  keys.insert(HgridBrickSerializer(c).structure_key());
  c = HgridBrickConfig{};
  c.builder.max_cell_triangles = 9;
  keys.insert(HgridBrickSerializer(c).structure_key());
  c = HgridBrickConfig{};
  c.builder.max_levels = 2;
  keys.insert(HgridBrickSerializer(c).structure_key());
  EXPECT_EQ(keys.size(), 7u);
  EXPECT_EQ(HgridBrickSerializer(HgridBrickConfig{}).structure_key().rfind("hgrid/", 0), 0u);
  auto made = make_brick_builder("hgrid", {{"triangle_test", "mt"}});
  ASSERT_TRUE(made.ok());
  ASSERT_NE((*made)->serializer(), nullptr);
  EXPECT_NE((*made)->serializer()->structure_key().find("triangle_test=mt"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
