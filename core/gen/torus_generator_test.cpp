#include "core/gen/torus_generator.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/gen/gen_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using gen_test::centroid_of;
using gen_test::closed_oriented_problem;
using gen_test::collect_spec;
using gen_test::normal_of;

TEST(TorusGenerator, Counts) {
  EXPECT_EQ(collect_spec("gen:torus").size(), 2u * 64 * 32);
  EXPECT_EQ(collect_spec("gen:torus?nu=3&nv=3").size(), 18u);
  EXPECT_EQ(collect_spec("gen:torus?nu=100&nv=7").size(), 1400u);
  EXPECT_EQ(*generator_triangle_count("gen:torus?nu=32768&nv=32768"), 2ull * 32768 * 32768);
}

TEST(TorusGenerator, WatertightAndConsistentlyOriented) {
  for (const std::string spec : {"gen:torus", "gen:torus?nu=3&nv=3", "gen:torus?nu=97&nv=13&major=3&minor=1",
                                 "gen:torus?major=10&minor=0.5&cx=100&cy=-7&cz=3.3&nu=128&nv=48"}) {
    SCOPED_TRACE(spec);
    EXPECT_EQ(closed_oriented_problem(collect_spec(spec)), "");
  }
}

TEST(TorusGenerator, NormalsPointOutOfTheTube) {
  const double major = 2.0, minor = 0.5;
  const Vec3d center(1, 2, 3);
  const auto tris = collect_spec("gen:torus?major=2&minor=0.5&cx=1&cy=2&cz=3&nu=40&nv=20");
  ASSERT_EQ(tris.size(), 1600u);
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const Vec3d p = centroid_of(tris[i]) - center;
    // Nearest point on the tube's axis (circle of radius major in the xz plane).
    const double rxz = std::hypot(p.x, p.z);
    const Vec3d axis(p.x / rxz * major, 0.0, p.z / rxz * major);
    ASSERT_GT(dot(normal_of(tris[i]), p - axis), 0.0) << "triangle " << i;
    ASSERT_NEAR(length(p - axis), minor, 0.05);
  }
}

TEST(TorusGenerator, ParameterErrors) {
  for (const auto& [spec, param] :
       {std::pair{"gen:torus?nu=2", "'nu'"}, std::pair{"gen:torus?nv=40000", "'nv'"},
        std::pair{"gen:torus?minor=1", "'minor'"}, std::pair{"gen:torus?major=0.1", "'minor'"},
        std::pair{"gen:torus?major=-1", "'major'"}}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(g.status().message().find(param), std::string::npos) << g.status().message();
    EXPECT_NE(g.status().message().find("gen:torus"), std::string::npos) << g.status().message();
  }
}

TEST(TorusGenerator, RestreamableAndSinkErrorsPropagate) {
  gen_test::expect_restreamable_and_sink_errors_propagate("gen:torus?nu=128&nv=64");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
