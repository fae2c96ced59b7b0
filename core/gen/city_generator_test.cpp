#include "core/gen/city_generator.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>

#include "core/gen/gen_test_util.h"
#include "core/gen/generator_factory.h"
#include "core/util/cancellation.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using gen_test::collect_spec;

std::unique_ptr<CityGenerator> make_city(const std::string& spec) {
  auto parsed = parse_gen_spec(spec);
  EXPECT_TRUE(parsed.ok()) << parsed.status().to_string();
  auto city = CityGenerator::create(*parsed);
  EXPECT_TRUE(city.ok()) << city.status().to_string();
  return city.ok() ? std::move(city).value() : nullptr;
}

TEST(CityGenerator, CountIsCopiesTimesBase) {
  EXPECT_EQ(collect_spec("gen:city?of=(gen:sphere?level=1)&copies=7").size(), 7u * 80);
  EXPECT_EQ(collect_spec("gen:city?copies=3").size(), 3u * 1280);  // default base: sphere level 3
  EXPECT_EQ(*generator_triangle_count("gen:city"), 100u * 1280);
  EXPECT_EQ(*generator_triangle_count("gen:city?of=(gen:torus?nu=10&nv=5)&copies=40000000"), 4'000'000'000u);
}

TEST(CityGenerator, TrianglesAreCopyMajorTransformsOfTheBase) {
  auto city = make_city("gen:city?of=(gen:sphere?level=1&radius=2&cy=5)&copies=7&seed=3");
  ASSERT_NE(city, nullptr);
  const auto base = collect_spec("gen:sphere?level=1&radius=2&cy=5");
  ASSERT_EQ(city->base().triangle_count(), base.size());
  for (std::size_t k = 0; k < base.size(); ++k) ASSERT_EQ(city->base().triangle(k), base[k]);
  EXPECT_EQ(city->base().vertices.size(), 42u);  // welded: V = T/2 + 2 for a closed genus-0 mesh
  const auto tris = read_all(*city);
  ASSERT_TRUE(tris.ok());
  ASSERT_EQ(tris->size(), 7 * base.size());
  for (int64_t c = 0; c < 7; ++c) {
    const CopyTransform t = city->copy_transform(c);
    EXPECT_GE(t.scale, 0.5);
    EXPECT_LE(t.scale, 1.5);
    for (std::size_t k = 0; k < base.size(); ++k) {
      const Triangle& got = (*tris)[static_cast<std::size_t>(c) * base.size() + k];
      ASSERT_EQ(got, (Triangle{t.apply(base[k].v0), t.apply(base[k].v1), t.apply(base[k].v2)}))
          << "copy " << c << " triangle " << k;
      // Similarity transform: every edge scaled by t.scale.
      const double l0 = length(Vec3d(base[k].v1) - Vec3d(base[k].v0));
      ASSERT_NEAR(length(Vec3d(got.v1) - Vec3d(got.v0)), t.scale * l0, 1e-5 * l0 + 1e-5);
    }
  }
}

// tilt turns the whole city about the x axis: tilt=0 is bitwise the city
// without it, and a tilted vertex is the untilted one turned (to float
// rounding); x never changes. Out-of-range tilts are errors naming the parameter.
TEST(CityGenerator, TiltTurnsTheWholeCityAboutX) {
  const std::string base = "gen:city?of=(gen:sphere?level=1)&copies=9&seed=2";
  const auto flat = collect_spec(base);
  EXPECT_EQ(collect_spec(base + "&tilt=0"), flat);
  const auto tilted = collect_spec(base + "&tilt=30");
  ASSERT_EQ(tilted.size(), flat.size());
  const double c = std::cos(std::numbers::pi / 6), s = std::sin(std::numbers::pi / 6);
  for (std::size_t k = 0; k < flat.size(); ++k) {
    for (int v = 0; v < 3; ++v) {
      const Vec3f& a = v == 0 ? flat[k].v0 : (v == 1 ? flat[k].v1 : flat[k].v2);
      const Vec3f& b = v == 0 ? tilted[k].v0 : (v == 1 ? tilted[k].v1 : tilted[k].v2);
      ASSERT_EQ(a.x, b.x) << "triangle " << k;
      const double scale = 1e-5 * (std::fabs(a.y) + std::fabs(a.z) + 1);
      ASSERT_NEAR(b.y, c * a.y - s * a.z, scale) << "triangle " << k;
      ASSERT_NEAR(b.z, s * a.y + c * a.z, scale) << "triangle " << k;
    }
  }
  for (const char* bad : {"&tilt=91", "&tilt=-90.5", "&tilt=x"}) {
    auto parsed = parse_gen_spec(base + bad);
    ASSERT_TRUE(parsed.ok());
    auto city = CityGenerator::create(*parsed);
    ASSERT_FALSE(city.ok()) << bad;
    EXPECT_NE(city.status().message().find("tilt"), std::string::npos) << city.status().message();
  }
}

TEST(CityGenerator, CopiesDifferAndAreSpreadOnAGrid) {
  auto city = make_city("gen:city?of=(gen:sphere?level=2)&copies=50&seed=5");
  ASSERT_NE(city, nullptr);
  const auto tris = read_all(*city);
  ASSERT_TRUE(tris.ok());
  const std::size_t b = city->base().triangle_count();
  std::set<float> scales, centres_x, centres_z;
  Aabb all;
  for (int64_t c = 0; c < 50; ++c) {
    const CopyTransform t = city->copy_transform(c);
    scales.insert(static_cast<float>(t.scale));
    Aabb box;
    for (std::size_t k = 0; k < b; ++k) box.extend((*tris)[c * b + k].bounds());
    centres_x.insert(box.center().x);
    centres_z.insert(box.center().z);
    all.extend(box);
  }
  EXPECT_EQ(scales.size(), 50u);
  EXPECT_EQ(centres_x.size(), 50u);
  // 8 x 8 cells of 2.5 x the base diagonal (2 * sqrt(3) for a unit sphere's box, a bit less for the
  // icosphere).
  EXPECT_GT(all.extent().x, 6 * city->cell_size());
  EXPECT_LT(all.extent().x, 9 * city->cell_size());
  EXPECT_GT(city->cell_size(), 2.5 * 3.0);
  EXPECT_LE(city->cell_size(), 2.5 * 2.0 * std::sqrt(3.0));
  // Explicit spacing.
  EXPECT_EQ(make_city("gen:city?copies=4&spacing=100")->cell_size(), 100.0);
}

TEST(CityGenerator, DeterministicPerSeed) {
  const std::string spec = "gen:city?of=(gen:torus?nu=12&nv=6)&copies=30&seed=9";
  const auto a = collect_spec(spec);
  EXPECT_EQ(a, collect_spec(spec));
  EXPECT_NE(a, collect_spec("gen:city?of=(gen:torus?nu=12&nv=6)&copies=30&seed=10"));
  // Copy c does not depend on how many copies there are (only the grid side does).
  auto c30 = make_city(spec);
  auto c31 = make_city("gen:city?of=(gen:torus?nu=12&nv=6)&copies=31&seed=9");
  EXPECT_EQ(c30->copy_transform(4).scale, c31->copy_transform(4).scale);
}

TEST(CityGenerator, PercentEncodedAndParenthesisedBaseAgree) {
  EXPECT_EQ(collect_spec("gen:city?of=(gen:sphere?level=1&radius=3)&copies=4"),
            collect_spec("gen:city?of=gen%3Asphere%3Flevel%3D1%26radius%3D3&copies=4"));
}

TEST(CityGenerator, NestedCity) {
  const auto tris = collect_spec("gen:city?of=(gen:city?of=(gen:sphere?level=0)&copies=3)&copies=2");
  EXPECT_EQ(tris.size(), 2u * 3 * 20);
}

TEST(CityGenerator, BaseFromAFile) {
  const std::string path = ::testing::TempDir() + "/outcore_city_base_quad.obj";
  {
    std::ofstream obj(path);
    obj << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";  // one quad: two triangles
  }
  auto city = make_city("gen:city?copies=5&of=" + path);
  ASSERT_NE(city, nullptr);
  ASSERT_EQ(city->base().triangle_count(), 2u);
  EXPECT_EQ(city->base().triangle(0), (Triangle{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}}));
  EXPECT_EQ(city->base().triangle(1), (Triangle{{0, 0, 0}, {1, 1, 0}, {0, 1, 0}}));
  EXPECT_EQ(city->triangle_count(), 10u);
  EXPECT_EQ(city->cell_size(), 2.5 * std::sqrt(2.0));
  EXPECT_EQ(read_all(*city)->size(), 10u);
  std::filesystem::remove(path);
}

TEST(CityGenerator, Errors) {
  // Primitive ids must fit in uint32: checked before reading a generated base.
  for (const std::string spec :
       {"gen:city?of=(gen:sphere?level=12)&copies=13", "gen:city?of=(gen:sphere?level=0)&copies=214748365"}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_EQ(g.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(g.status().message().find("'copies'"), std::string::npos) << g.status().message();
  }
  EXPECT_EQ(*generator_triangle_count("gen:city?of=(gen:sphere?level=0)&copies=214748364"), 4294967280u);

  for (const auto& [spec, fragment] :
       {std::pair{"gen:city?copies=0", "'copies'"}, std::pair{"gen:city?copies=1000000001", "'copies'"},
        std::pair{"gen:city?spacing=0", "'spacing'"}, std::pair{"gen:city?of=", "'of'"},
        std::pair{"gen:city?of=(gen:sphere?level=99)", "'level'"},
        std::pair{"gen:city?of=(gen:nope)", "'of'"},
        std::pair{"gen:city?of=/nonexistent/dir/base.obj", "'of'"},
        std::pair{"gen:city?of=base.stl", "'of'"}}) {
    auto g = make_generator(spec);
    ASSERT_FALSE(g.ok()) << spec;
    EXPECT_NE(g.status().message().find(fragment), std::string::npos) << g.status().message();
  }
  // A nested generator's error keeps its code and gains the context.
  auto nested = make_generator("gen:city?of=(gen:nope)");
  EXPECT_EQ(nested.status().code(), StatusCode::kNotFound);
  EXPECT_NE(nested.status().message().find("gen:city: parameter 'of'"), std::string::npos);
}

TEST(CityGenerator, RestreamableAndSinkErrorsPropagate) {
  gen_test::expect_restreamable_and_sink_errors_propagate("gen:city?of=(gen:sphere?level=2)&copies=100");
}

// Throughput with a counting sink; run with --gtest_also_run_disabled_tests.
class CountingSink final : public TriangleSink {
 public:
  Status consume(std::span<const Triangle> batch) override {
    count += batch.size();
    if (!batch.empty()) checksum += batch.back().v2.x;
    return Status::Ok();
  }
  uint64_t count = 0;
  double checksum = 0;
};

// A huge base takes minutes to read: an interrupt must stop the reading itself.
TEST(CityGenerator, ReadingTheBaseStopsOnCancellation) {
  request_cancel();
  auto city = make_generator("gen:city?of=(gen:sphere?level=5)&copies=2");
  reset_cancel();
  ASSERT_FALSE(city.ok());
  EXPECT_EQ(city.status().code(), StatusCode::kCancelled);
  EXPECT_NE(city.status().message().find("interrupted"), std::string::npos) << city.status().to_string();
}

TEST(CityGenerator, BaseMemoryLimitRefusesUpFrontOrWhileReadingAndNamesTheBase) {
  GeneratorOptions options;
  options.mesh_memory_bytes = 100'000;
  options.mesh_memory_origin = "the test's limit";
  // 20 * 4^5 = 20480 triangles: 240 KB of triples before any vertex.
  auto up_front = make_generator("gen:city?of=(gen:sphere?level=5)&copies=2", options);
  ASSERT_FALSE(up_front.ok());
  EXPECT_EQ(up_front.status().code(), StatusCode::kResourceExhausted);
  for (const char* part : {"'gen:sphere?level=5'", "at least 1 MiB", "the test's limit"})
    EXPECT_NE(up_front.status().message().find(part), std::string::npos) << up_front.status().to_string();
  // 5120 triangles: 60 KB of triples fit, with 2562 vertices and the table they do not.
  auto while_read = make_generator("gen:city?of=(gen:sphere?level=4)&copies=2", options);
  ASSERT_FALSE(while_read.ok());
  EXPECT_EQ(while_read.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(while_read.status().message().find("of 5120 triangles"), std::string::npos)
      << while_read.status().to_string();
  // A nested base is held under the same limit.
  EXPECT_EQ(
      make_generator("gen:city?of=(gen:city?of=(gen:sphere?level=5)&copies=2)", options).status().code(),
      StatusCode::kResourceExhausted);
  // Under the limit nothing changes.
  options.mesh_memory_bytes = 1 << 20;
  auto fits = make_generator("gen:city?of=(gen:sphere?level=4)&copies=2", options);
  ASSERT_TRUE(fits.ok()) << fits.status().to_string();
}

TEST(GeneratorBench, DISABLED_Throughput) {
  for (const std::string spec :
       {"gen:city?of=(gen:sphere?level=5)&copies=20000", "gen:city?of=(gen:sphere?level=3)&copies=200000",
        "gen:city?of=(gen:torus?nu=64&nv=32)&copies=50000", "gen:sphere?level=11",
        "gen:torus?nu=8192&nv=8192", "gen:terrain?n=8192", "gen:stadium?level=11"}) {
    const auto cpu_now = [] {
      timespec ts{};
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
      return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
    };
    const auto t0 = std::chrono::steady_clock::now();
    auto g = make_generator(spec);
    ASSERT_TRUE(g.ok()) << g.status().to_string();
    const auto t1 = std::chrono::steady_clock::now();
    const double c1 = cpu_now();
    CountingSink sink;
    ASSERT_TRUE((*g)->stream(sink).ok());
    const double cpu = cpu_now() - c1;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    std::printf(
        "%-50s %10llu tris  setup %.3f s  wall %6.2f s %6.1f M/s  cpu %6.2f s %6.1f M/s (checksum %g)\n",
        spec.c_str(), static_cast<unsigned long long>(sink.count),
        std::chrono::duration<double>(t1 - t0).count(), wall, static_cast<double>(sink.count) / wall / 1e6,
        cpu, static_cast<double>(sink.count) / cpu / 1e6, sink.checksum);
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
