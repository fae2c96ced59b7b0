#include "core/gen/generator_factory.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>

#include "core/gen/gen_spec.h"
#include "core/gen/gen_test_util.h"
#include "core/source/source_factory.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(GeneratorFactory, Names) {
  EXPECT_EQ(generator_names(), (std::vector<std::string>{"city", "sphere", "stadium", "terrain", "torus"}));
}

TEST(GeneratorFactory, EveryNameCreatesWithDefaults) {
  for (const std::string& name : generator_names()) {
    auto g = make_typed_generator("gen:" + name);
    ASSERT_TRUE(g.ok()) << name << ": " << g.status().to_string();
    EXPECT_EQ((*g)->description(), "gen:" + name);
    EXPECT_GT((*g)->triangle_count(), 0u);
  }
}

// emit_range over any cut of [0, count) concatenates to exactly emit()'s
// triangles: ranges at copy/row boundaries, inside them, empty ones, and a
// last bound past the end.
TEST(GeneratorRanges, ConcatenatedRangesAreBitIdenticalToTheWholeStreamForEveryGenerator) {
  for (const std::string spec : {"gen:city?of=(gen:sphere?level=1)&copies=13", "gen:terrain?n=37",
                                 "gen:sphere?level=3", "gen:torus", "gen:stadium"}) {
    SCOPED_TRACE(spec);
    auto g = make_typed_generator(spec);
    ASSERT_TRUE(g.ok()) << g.status().to_string();
    const Generator& gen = **g;
    const auto whole = read_all(**g);
    ASSERT_TRUE(whole.ok());
    const uint64_t n = gen.triangle_count();
    ASSERT_EQ(whole->size(), n);
    const uint64_t step = gen.range_granularity();
    for (std::vector<uint64_t> cuts : {std::vector<uint64_t>{0, n},
                                       {0, step, step, 2 * step + 1, n / 2, n / 2 + 7, n - 1, n + 5},
                                       {0, 1, 3, step - 1, 3 * step, n}}) {
      std::sort(cuts.begin(), cuts.end());
      std::vector<Triangle> joined;
      CallbackSink sink([&](std::span<const Triangle> batch) {
        joined.insert(joined.end(), batch.begin(), batch.end());
        return Status::Ok();
      });
      for (size_t i = 0; i + 1 < cuts.size(); ++i) {
        const uint64_t first = std::min(cuts[i], n), last = cuts[i + 1];
        auto batcher = std::make_unique<TriangleBatcher>(sink);
        ASSERT_TRUE(gen.emit_range(first, last, *batcher).ok());
        ASSERT_TRUE(batcher->finish().ok());
      }
      ASSERT_EQ(joined.size(), n);
      EXPECT_TRUE(joined == *whole);
    }
  }
}

TEST(GeneratorFactory, UnknownGeneratorIsNotFoundAndListsKnownOnes) {
  for (const std::string spec : {"gen:teapot", "gen:teapot?level=1", "gen:teapot?garbage", "gen:Sphere"}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok());
    EXPECT_EQ(g.status().code(), StatusCode::kNotFound) << g.status().to_string();
    std::string quoted = "'";
    quoted.append(gen_spec_name(spec)).push_back('\'');
    EXPECT_NE(g.status().message().find(quoted), std::string::npos);
    EXPECT_NE(g.status().message().find("known: city, sphere, stadium, terrain, torus"), std::string::npos)
        << g.status().message();
  }
  EXPECT_EQ(make_generator("gen:").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(make_generator("sphere").status().code(), StatusCode::kInvalidArgument);
}

TEST(GeneratorFactory, ParameterErrorsNameGeneratorAndParameter) {
  const auto expect = [](const std::string& spec, std::initializer_list<const char*> fragments) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument) << spec;
    for (const char* f : fragments) {
      EXPECT_NE(g.status().message().find(f), std::string::npos) << g.status().message() << " lacks " << f;
    }
  };
  expect("gen:sphere?lvl=2", {"gen:sphere", "'lvl'", "known: level, radius, cx, cy, cz"});
  expect("gen:torus?radius=2", {"gen:torus", "'radius'", "known: major, minor, nu, nv, cx, cy, cz"});
  expect("gen:terrain?level=2", {"gen:terrain", "'level'", "known: n, size, height, octaves, seed"});
  expect("gen:city?level=2", {"gen:city", "'level'", "known: of, copies, seed, spacing"});
  expect("gen:stadium?radius=2", {"gen:stadium", "'radius'", "known: size, level, object, segments"});
  expect("gen:sphere?level=abc", {"gen:sphere", "'level'", "'abc'"});
  expect("gen:sphere?level=13", {"gen:sphere", "'level'", "out of range"});
  expect("gen:sphere?level=1&level=2", {"gen:sphere", "'level'", "twice"});
}

TEST(GeneratorFactory, TriangleCountMatchesStream) {
  for (const std::string spec :
       {"gen:sphere?level=2", "gen:torus?nu=9&nv=5", "gen:terrain?n=13", "gen:stadium?level=1&segments=3",
        "gen:city?of=(gen:torus?nu=5&nv=3)&copies=11"}) {
    auto count = generator_triangle_count(spec);
    ASSERT_TRUE(count.ok()) << spec;
    EXPECT_EQ(*count, gen_test::collect_spec(spec).size()) << spec;
  }
}

TEST(GeneratorFactory, ReachableThroughOpenTriangleSource) {
  auto source = open_triangle_source("gen:sphere?level=1");
  ASSERT_TRUE(source.ok()) << source.status().to_string();
  EXPECT_EQ((*source)->description(), "gen:sphere?level=1");
  auto tris = read_all(**source);
  ASSERT_TRUE(tris.ok());
  EXPECT_EQ(tris->size(), 80u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
