#include "core/gen/sphere_generator.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/gen/gen_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using gen_test::centroid_of;
using gen_test::closed_oriented_problem;
using gen_test::collect_spec;
using gen_test::normal_of;

TEST(SphereGenerator, CountsPerLevel) {
  for (int level : {0, 1, 2, 3, 4, 6}) {
    const std::string spec = "gen:sphere?level=" + std::to_string(level);
    const uint64_t expected = 20ull << (2 * level);
    EXPECT_EQ(collect_spec(spec).size(), expected) << spec;
    auto count = generator_triangle_count(spec);
    ASSERT_TRUE(count.ok());
    EXPECT_EQ(*count, expected);
  }
  EXPECT_EQ(*generator_triangle_count("gen:sphere"), 20u * 64u);  // default level 3
  EXPECT_EQ(*generator_triangle_count("gen:sphere?level=12"), 335544320u);
}

TEST(SphereGenerator, VerticesOnTheSphere) {
  for (const auto& [spec, center, radius] :
       {std::tuple{std::string("gen:sphere?level=5"), Vec3d(0, 0, 0), 1.0},
        std::tuple{std::string("gen:sphere?level=4&radius=3.5&cx=1&cy=-2&cz=0.5"), Vec3d(1, -2, 0.5), 3.5},
        std::tuple{std::string("gen:sphere?level=3&radius=1e-3"), Vec3d(0, 0, 0), 1e-3}}) {
    SCOPED_TRACE(spec);
    const auto tris = collect_spec(spec);
    ASSERT_FALSE(tris.empty());
    double worst = 0;
    for (const Triangle& t : tris) {
      for (const Vec3f& v : {t.v0, t.v1, t.v2}) {
        worst = std::max(worst, std::abs(length(Vec3d(v) - center) - radius) / radius);
      }
    }
    EXPECT_LT(worst, 1e-6);
  }
}

TEST(SphereGenerator, WatertightAndConsistentlyOriented) {
  for (const std::string spec :
       {"gen:sphere?level=0", "gen:sphere?level=1", "gen:sphere?level=3",
        "gen:sphere?level=5&radius=7&cx=100&cy=-3&cz=12.25", "gen:sphere?level=6&radius=0.001"}) {
    SCOPED_TRACE(spec);
    const auto tris = collect_spec(spec);
    EXPECT_EQ(closed_oriented_problem(tris), "");
  }
}

TEST(SphereGenerator, NormalsPointOutward) {
  const Vec3d center(5, -1, 2);
  const auto tris = collect_spec("gen:sphere?level=4&radius=2&cx=5&cy=-1&cz=2");
  ASSERT_EQ(tris.size(), 5120u);
  for (std::size_t i = 0; i < tris.size(); ++i) {
    ASSERT_GT(dot(normal_of(tris[i]), centroid_of(tris[i]) - center), 0.0) << "triangle " << i;
  }
}

TEST(SphereGenerator, DepthFirstOrderRefinesTheLevelAbove) {
  // Triangles 4k .. 4k+3 of level L subdivide triangle k of level L-1 and keep
  // its corners bit for bit (child 0 at v0, child 1 at v1, child 2 at v2).
  for (int level = 1; level <= 4; ++level) {
    const auto parent = collect_spec("gen:sphere?radius=2.5&cx=1&level=" + std::to_string(level - 1));
    const auto child = collect_spec("gen:sphere?radius=2.5&cx=1&level=" + std::to_string(level));
    ASSERT_EQ(child.size(), 4 * parent.size());
    for (std::size_t k = 0; k < parent.size(); ++k) {
      ASSERT_EQ(child[4 * k].v0, parent[k].v0) << level << " " << k;
      ASSERT_EQ(child[4 * k + 1].v1, parent[k].v1) << level << " " << k;
      ASSERT_EQ(child[4 * k + 2].v2, parent[k].v2) << level << " " << k;
      // The centre child is made of the three edge midpoints.
      ASSERT_EQ(child[4 * k + 3], (Triangle{child[4 * k].v1, child[4 * k + 1].v2, child[4 * k].v2}));
    }
  }
}

TEST(SphereGenerator, ConfigDefaultsAndErrors) {
  const GenSpec spec{"gen:sphere", "sphere", {}};
  auto c = SphereConfig::parse(spec);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->level, 3);
  EXPECT_EQ(c->radius, 1.0);
  EXPECT_EQ(c->center, Vec3d(0, 0, 0));
  for (const char* bad :
       {"gen:sphere?level=13", "gen:sphere?level=abc", "gen:sphere?radius=0", "gen:sphere?r=1"}) {
    auto g = make_generator(bad);
    ASSERT_FALSE(g.ok()) << bad;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(g.status().message().find("gen:sphere"), std::string::npos) << g.status().message();
  }
}

TEST(SphereGenerator, RestreamableAndSinkErrorsPropagate) {
  gen_test::expect_restreamable_and_sink_errors_propagate("gen:sphere?level=5");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
