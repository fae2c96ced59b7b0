#include "core/gen/stadium_generator.h"

#include <gtest/gtest.h>

#include "core/gen/gen_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using gen_test::centroid_of;
using gen_test::collect_spec;
using gen_test::normal_of;

TEST(StadiumGenerator, Counts) {
  // Floor 2 * 16^2 + 4 walls * 2 * 16 * 2 rows, then the level-6 sphere.
  EXPECT_EQ(collect_spec("gen:stadium").size(), 512u + 256u + 81920u);
  EXPECT_EQ(collect_spec("gen:stadium?segments=1&level=0").size(), 2u + 8u + 20u);
  EXPECT_EQ(collect_spec("gen:stadium?segments=40&level=2").size(), 2u * 1600 + 8u * 40 * 5 + 320u);
  EXPECT_EQ(*generator_triangle_count("gen:stadium?level=12&segments=1024"),
            2ull * 1024 * 1024 + 8ull * 1024 * 128 + 335544320ull);
}

TEST(StadiumGenerator, TinyObjectInAHugeEnclosure) {
  auto parsed = parse_gen_spec("gen:stadium?size=500&level=4&object=2");
  ASSERT_TRUE(parsed.ok());
  auto g = StadiumGenerator::create(*parsed);
  ASSERT_TRUE(g.ok());
  const auto tris = read_all(**g);
  ASSERT_TRUE(tris.ok());
  const std::size_t enclosure = (*g)->enclosure_triangle_count();
  ASSERT_EQ(tris->size(), enclosure + 5120);
  EXPECT_GE(enclosure, 100u);
  EXPECT_LE(enclosure, 1000u);

  Aabb outer, object;
  const Vec3d inside(0, 125, 0);  // centre of the box (walls 250 high)
  for (std::size_t k = 0; k < tris->size(); ++k) {
    const Triangle& t = (*tris)[k];
    if (k < enclosure) {
      outer.extend(t.bounds());
      ASSERT_GT(dot(normal_of(t), inside - centroid_of(t)), 0.0)
          << "enclosure triangle " << k << " faces outwards";
    } else {
      object.extend(t.bounds());
      ASSERT_GT(dot(normal_of(t), centroid_of(t) - Vec3d(0, 3, 0)), 0.0) << "object triangle " << k;
    }
  }
  EXPECT_EQ(outer.lo, Vec3f(-500, 0, -500));
  EXPECT_EQ(outer.hi, Vec3f(500, 250, 500));
  // The object: radius 2 centred at (0, 3, 0), above the floor.
  EXPECT_NEAR(object.lo.y, 1.0f, 0.05f);
  EXPECT_NEAR(object.hi.y, 5.0f, 0.05f);
  EXPECT_GT(object.lo.y, 0.0f);
  EXPECT_LT(object.extent().x, 4.01f);
  EXPECT_GT(outer.half_area(), 1e4 * object.half_area());
}

TEST(StadiumGenerator, ParameterErrors) {
  for (const auto& [spec, param] :
       {std::pair{"gen:stadium?size=0", "'size'"}, std::pair{"gen:stadium?level=13", "'level'"},
        std::pair{"gen:stadium?object=300", "'object'"}, std::pair{"gen:stadium?segments=0", "'segments'"},
        std::pair{"gen:stadium?segments=1025", "'segments'"},
        std::pair{"gen:stadium?teapot=1", "'teapot'"}}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(g.status().message().find(param), std::string::npos) << g.status().message();
    EXPECT_NE(g.status().message().find("gen:stadium"), std::string::npos) << g.status().message();
  }
}

TEST(StadiumGenerator, RestreamableAndSinkErrorsPropagate) {
  gen_test::expect_restreamable_and_sink_errors_propagate("gen:stadium?level=5");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
