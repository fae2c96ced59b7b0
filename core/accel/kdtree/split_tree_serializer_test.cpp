// The serialisers of the split-plane trees' payload (KdTreeBrickSerializer,
// BspBrickSerializer, OctreeBrickSerializer, QuadtreeBrickSerializer;
// split_tree_serializer.h), each: a saved and reloaded
// brick answers bitwise as the built one (every triangle test, models and generator scenes, degenerate
// triangles), reports the same memory and triangle count; truncated, padded,
// inflated and randomly corrupted payloads are errors or, where the damage
// leaves a valid tree, load and trace without a crash. Structure keys differ
// exactly when the config does.
#include "core/accel/bsp/bsp_brick_serializer.h"
#include "core/accel/kdtree/kd_tree_brick_serializer.h"
#include "core/accel/octree/octree_brick_serializer.h"
#include "core/accel/quadtree/quadtree_brick_serializer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/serializer_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::load_brick_from;
using serializer_test::expect_same_answers;
using serializer_test::save;
using serializer_test::unowned;

constexpr std::size_t kRays = 1500;

// Configs that each differ from the default in one builder field.
template <class Config>
std::vector<Config> cost_variants() {
  std::vector<Config> out(4);
  out[0].builder.traversal_cost = std::nextafter(1.0f, 2.0f);  // the smallest change still differs
  out[1].builder.intersection_cost = 40.0f;
  out[2].builder.empty_bonus = 0.25f;
  out[3].builder.max_depth = 20;
  return out;
}

struct KdTreeKind {
  using Config = KdTreeBrickConfig;
  using Accel = KdTreeBrickAccel;
  using Serializer = KdTreeBrickSerializer;
  using Node = KdNode;
  static constexpr const char* kName = "kdtree";
  static Node cycle() { return KdNode::inner(0, 0.0f, 0); }
  static std::vector<Config> variants() { return cost_variants<Config>(); }
};
struct BspKind {
  using Config = BspBrickConfig;
  using Accel = BspBrickAccel;
  using Serializer = BspBrickSerializer;
  using Node = BspNode;
  static constexpr const char* kName = "bsp";
  static Node cycle() { return BspNode::inner(0, 0.0f, 0); }
  static std::vector<Config> variants() { return cost_variants<Config>(); }
};
struct OctreeKind {
  using Config = OctreeBrickConfig;
  using Accel = OctreeBrickAccel;
  using Serializer = OctreeBrickSerializer;
  using Node = OctreeNode;
  static constexpr const char* kName = "octree";
  static Node cycle() { return OctreeNode::inner(0); }
  template <class Variant = Config>
  static std::vector<Variant> variants() {
    std::vector<Variant> out(2);
    out[0].builder.max_leaf_size = 4;
    out[1].builder.max_depth = 10;
    return out;
  }
};

struct QuadtreeKind {
  using Config = QuadtreeBrickConfig;
  using Accel = QuadtreeBrickAccel;
  using Serializer = QuadtreeBrickSerializer;
  using Node = QuadtreeNode;
  static constexpr const char* kName = "quadtree";
  static Node cycle() { return QuadtreeNode::inner(0, 0.0f, 0.0f); }
  static std::vector<Config> variants() { return OctreeKind::variants<Config>(); }
};

template <class Kind>
typename Kind::Config config_of(TriangleTest test) {
  typename Kind::Config config;
  config.triangle_test = test;
  return config;
}

template <class Kind>
std::unique_ptr<typename Kind::Accel> build(BrickData brick, const typename Kind::Config& config) {
  auto accel = Kind::Accel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return std::move(accel).value();
}

std::vector<Ray> rays_for(const Aabb& b, uint64_t seed) {
  auto rays = accel_test::rays_from_outside(b, kRays / 2, seed);
  const auto inside = accel_test::rays_from_inside(b, kRays - kRays / 2, seed + 1);
  rays.insert(rays.end(), inside.begin(), inside.end());
  for (std::size_t i = 0; i < rays.size(); i += 5) rays[i].tfar = 0.3f * length(b.extent());
  return rays;
}

template <class Kind>
class SplitTreeSerializer : public ::testing::Test {};
using Kinds = ::testing::Types<KdTreeKind, BspKind, OctreeKind, QuadtreeKind>;
TYPED_TEST_SUITE(SplitTreeSerializer, Kinds);

TYPED_TEST(SplitTreeSerializer, RoundTripAnswersBitwiseAndKeepsMemoryAndCounts) {
  using Kind = TypeParam;
  std::vector<std::pair<std::string, BrickData>> bricks;
  bricks.emplace_back("bunny", load_brick_from(accel_test::bunny_path()));
  bricks.emplace_back("torus", load_brick_from("gen:torus?nu=48&nv=24"));
  bricks.emplace_back("degenerate-heavy", accel_test::degenerate_heavy(3000, 7));
  for (const auto& [name, brick] : bricks) {
    const Aabb bounds = accel_test::bounds_of(brick);
    for (const TriangleTest test : kAllTriangleTests) {
      const std::string what = name + " " + std::string(triangle_test_name(test));
      const typename Kind::Serializer serializer(config_of<Kind>(test));
      BrickData copy = brick;
      copy.brick_id = 17;
      const auto built = build<Kind>(std::move(copy), config_of<Kind>(test));
      EXPECT_EQ(built->brick_id(), 17u);
      const std::string payload = save(serializer, *built);
      auto loaded = serializer.load(unowned(payload), 17, built->triangle_count());
      ASSERT_TRUE(loaded.ok()) << what << ": " << loaded.status().to_string();
      const auto& kd = dynamic_cast<const typename Kind::Accel&>(**loaded);
      EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes()) << what;
      EXPECT_EQ((*loaded)->triangle_count(), built->triangle_count()) << what;
      EXPECT_EQ(kd.brick_id(), 17u) << what;
      EXPECT_EQ(kd.triangle_test(), test) << what;
      EXPECT_EQ(kd.view().nodes.size(), built->view().nodes.size()) << what;
      expect_same_answers(*built, **loaded, rays_for(bounds, 99), what);
      // Vouched-for bytes load the same tree without the structural walk.
      auto trusted = serializer.load({payload, nullptr, true}, 17, built->triangle_count());
      ASSERT_TRUE(trusted.ok()) << what;
      expect_same_answers(*built, **trusted, rays_for(bounds, 98), what);
    }
  }
}

TYPED_TEST(SplitTreeSerializer, EmptyBrickRoundTrips) {
  using Kind = TypeParam;
  const typename Kind::Serializer serializer(config_of<Kind>(TriangleTest::kWatertight));
  const auto built = build<Kind>(BrickData{}, config_of<Kind>(TriangleTest::kWatertight));
  auto loaded = serializer.load(unowned(save(serializer, *built)), 0, 0);
  ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
  EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes());
}

TYPED_TEST(SplitTreeSerializer, MalformedPayloadsAreErrorsNamingTheBrick) {
  using Kind = TypeParam;
  const BrickData brick = load_brick_from("gen:sphere?level=2");
  const typename Kind::Serializer serializer(config_of<Kind>(TriangleTest::kWatertight));
  const auto built = build<Kind>(brick, config_of<Kind>(TriangleTest::kWatertight));
  const std::string payload = save(serializer, *built);
  const uint32_t n = built->triangle_count();
  const auto expect_error = [&](std::string_view bytes, uint32_t triangles, const std::string& what) {
    auto loaded = serializer.load(unowned(bytes), 42, triangles);
    ASSERT_FALSE(loaded.ok()) << what;
    EXPECT_EQ(loaded.status().code(), StatusCode::kInvalidArgument) << what;
    EXPECT_NE(loaded.status().message().find("brick 42"), std::string::npos) << loaded.status().message();
  };
  for (const std::size_t cut : {std::size_t{0}, std::size_t{1}, std::size_t{40}, std::size_t{64},
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
  std::string nan_bounds = payload;
  const float nan = std::nanf("");
  std::memcpy(nan_bounds.data() + 32, &nan, sizeof(nan));
  expect_error(nan_bounds, n, "NaN bounds");
  // The root made its own child: a cycle the walk would never leave.
  std::string cycle = payload;
  const typename Kind::Node self = Kind::cycle();
  std::memcpy(cycle.data() + 64, &self, sizeof(self));
  expect_error(cycle, n, "a node pointing back at the root");
  // A payload saved with another triangle test.
  const typename Kind::Serializer mt(config_of<Kind>(TriangleTest::kMt));
  const std::string mt_payload = save(mt, *build<Kind>(brick, config_of<Kind>(TriangleTest::kMt)));
  auto wrong = serializer.load(unowned(mt_payload), 0, n);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("triangle test"), std::string::npos) << wrong.status().message();
  // Saving a brick of another config, or of another structure, is refused.
  std::ostringstream out;
  EXPECT_FALSE(serializer.save(*build<Kind>(brick, config_of<Kind>(TriangleTest::kMt)), out).ok());
  auto bvh = make_brick_builder("bvh", {});
  ASSERT_TRUE(bvh.ok());
  auto bvh_brick = (*bvh)->build(BrickData(brick));
  ASSERT_TRUE(bvh_brick.ok());
  EXPECT_FALSE(serializer.save(**bvh_brick, out).ok());
}

// Random byte flips anywhere in the payload: each load is an error or a tree
// that passes validate(), and tracing a loaded one never crashes (ASan and
// UBSan in CI see to the "never").
TYPED_TEST(SplitTreeSerializer, FuzzedPayloadsNeverCrash) {
  using Kind = TypeParam;
  const BrickData brick = load_brick_from("gen:torus?nu=24&nv=12");
  const typename Kind::Serializer serializer(config_of<Kind>(TriangleTest::kWatertight));
  const auto built = build<Kind>(brick, config_of<Kind>(TriangleTest::kWatertight));
  const std::string payload = save(serializer, *built);
  // The header and the first nodes, where damage matters most.
  const auto outcome =
      serializer_test::fuzz(serializer, payload, built->triangle_count(),
                            rays_for(accel_test::bounds_of(brick), 3), 64 + sizeof(typename Kind::Node) * 64);
  EXPECT_GT(outcome.refused, 0u);
  EXPECT_GT(outcome.loaded, 0u);
}

TYPED_TEST(SplitTreeSerializer, StructureKeysDifferExactlyWhenTheConfigDoes) {
  using Kind = TypeParam;
  using Serializer = typename Kind::Serializer;
  std::set<std::string> keys;
  for (const TriangleTest test : kAllTriangleTests)
    keys.insert(Serializer(config_of<Kind>(test)).structure_key());
  const auto variants = Kind::variants();
  for (const auto& config : variants) keys.insert(Serializer(config).structure_key());
  EXPECT_EQ(keys.size(), 3 + variants.size());
  EXPECT_EQ(Serializer(typename Kind::Config{}).structure_key().rfind(std::string(Kind::kName) + "/", 0), 0u);
}

TEST(SplitTreeSerializerKeys, TheBspKeyNamesItsDirections) {
  BspBrickConfig seven;
  seven.builder.directions = 7;
  EXPECT_NE(BspBrickSerializer(seven).structure_key(), BspBrickSerializer(BspBrickConfig{}).structure_key());
}

TYPED_TEST(SplitTreeSerializer, TheFactorysBuilderHasOne) {
  auto made = make_brick_builder(TypeParam::kName, {{"triangle_test", "mt"}});
  ASSERT_TRUE(made.ok());
  ASSERT_NE((*made)->serializer(), nullptr);
  EXPECT_NE((*made)->serializer()->structure_key().find("triangle_test=mt"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
