#include "core/gen/terrain_generator.h"

#include <gtest/gtest.h>

#include "core/gen/gen_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using gen_test::collect_spec;
using gen_test::normal_of;

TEST(TerrainGenerator, Counts) {
  EXPECT_EQ(collect_spec("gen:terrain?n=1").size(), 2u);
  EXPECT_EQ(collect_spec("gen:terrain?n=37").size(), 2u * 37 * 37);
  EXPECT_EQ(*generator_triangle_count("gen:terrain"), 2u * 256 * 256);
  EXPECT_EQ(*generator_triangle_count("gen:terrain?n=46340"), 2ull * 46340 * 46340);
  auto too_big = make_generator("gen:terrain?n=46341");
  ASSERT_FALSE(too_big.ok());
  EXPECT_NE(too_big.status().message().find("'n'"), std::string::npos);
}

TEST(TerrainGenerator, DeterministicPerSeed) {
  const auto a = collect_spec("gen:terrain?n=64&seed=7");
  const auto b = collect_spec("gen:terrain?n=64&seed=7");
  const auto c = collect_spec("gen:terrain?n=64&seed=8");
  const auto d = collect_spec("gen:terrain?n=64&seed=7&octaves=3");
  ASSERT_EQ(a.size(), 2u * 64 * 64);
  EXPECT_EQ(a, b);
  ASSERT_EQ(c.size(), a.size());
  EXPECT_NE(a, c);
  EXPECT_NE(a, d);
  // Only heights differ between seeds: x and z are the same grid.
  std::size_t differing_heights = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].v0.x, c[k].v0.x);
    EXPECT_EQ(a[k].v0.z, c[k].v0.z);
    differing_heights += a[k].v0.y != c[k].v0.y;
  }
  EXPECT_GT(differing_heights, a.size() / 2);
}

TEST(TerrainGenerator, NeighbouringCellsShareBitIdenticalVertices) {
  const int n = 48;
  const auto tris = collect_spec("gen:terrain?n=48&size=123.5&height=17&octaves=9&seed=3");
  ASSERT_EQ(tris.size(), 2u * n * n);
  struct Cell {
    Vec3f p00, p10, p01, p11;
  };
  const auto cell = [&](int i, int j) {
    const Triangle& t0 = tris[2 * (static_cast<std::size_t>(j) * n + i)];
    const Triangle& t1 = tris[2 * (static_cast<std::size_t>(j) * n + i) + 1];
    EXPECT_EQ(t0.v0, t1.v0);
    EXPECT_EQ(t0.v2, t1.v1);
    return Cell{t0.v0, t1.v2, t0.v1, t0.v2};
  };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const Cell c = cell(i, j);
      if (i + 1 < n) {
        const Cell r = cell(i + 1, j);
        ASSERT_EQ(gen_test::key_of(r.p00), gen_test::key_of(c.p10));
        ASSERT_EQ(gen_test::key_of(r.p01), gen_test::key_of(c.p11));
      }
      if (j + 1 < n) {
        const Cell u = cell(i, j + 1);
        ASSERT_EQ(gen_test::key_of(u.p00), gen_test::key_of(c.p01));
        ASSERT_EQ(gen_test::key_of(u.p10), gen_test::key_of(c.p11));
      }
    }
  }
}

TEST(TerrainGenerator, FlatWideAndFacingUp) {
  auto g = TerrainGenerator::create(*parse_gen_spec("gen:terrain?n=64&size=1000&height=50&seed=11"));
  ASSERT_TRUE(g.ok());
  const auto tris = collect_spec("gen:terrain?n=64&size=1000&height=50&seed=11");
  Aabb box;
  for (const Triangle& t : tris) {
    box.extend(t.bounds());
    ASSERT_GT(normal_of(t).y, 0.0);
  }
  EXPECT_EQ(box.lo.x, -500.0f);
  EXPECT_EQ(box.hi.x, 500.0f);
  EXPECT_EQ(box.lo.z, -500.0f);
  EXPECT_EQ(box.hi.z, 500.0f);
  EXPECT_GE(box.lo.y, -50.0f);
  EXPECT_LE(box.hi.y, 50.0f);
  EXPECT_GT(box.hi.y - box.lo.y, 10.0f) << "not flat: some relief expected";
  // height_at() is the emitted height: cell (i, j) = 5, 9 starts at its p00.
  const Triangle& t = tris[2 * (9 * 64 + 5)];
  EXPECT_EQ(t.v0.y, static_cast<float>((*g)->height_at(5, 9)));
  EXPECT_EQ(tris[0].v0.y, static_cast<float>((*g)->height_at(0, 0)));
}

TEST(TerrainGenerator, ZeroHeightIsFlat) {
  for (const Triangle& t : collect_spec("gen:terrain?n=8&height=0")) {
    EXPECT_EQ(t.v0.y, 0.0f);
    EXPECT_EQ(t.v1.y, 0.0f);
    EXPECT_EQ(t.v2.y, 0.0f);
  }
}

TEST(TerrainGenerator, ParameterErrors) {
  for (const auto& [spec, param] :
       {std::pair{"gen:terrain?n=0", "'n'"}, std::pair{"gen:terrain?octaves=17", "'octaves'"},
        std::pair{"gen:terrain?size=0", "'size'"}, std::pair{"gen:terrain?height=-1", "'height'"},
        std::pair{"gen:terrain?seed=x", "'seed'"}, std::pair{"gen:terrain?cells=3", "'cells'"}}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(g.status().message().find(param), std::string::npos) << g.status().message();
  }
}

TEST(TerrainGenerator, RestreamableAndSinkErrorsPropagate) {
  gen_test::expect_restreamable_and_sink_errors_propagate("gen:terrain?n=100");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
