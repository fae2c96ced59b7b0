#include "core/accel/brick_accel_factory.h"

#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/bvh_brick.h"
#include "core/accel/embree_brick.h"
#include "core/accel/embree_device.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

const EmbreeBrickConfig& embree_config(const BrickBuilder& builder) {
  return dynamic_cast<const EmbreeBrickBuilder&>(builder).config();
}

TEST(BrickAccelFactory, NamesAndDefaults) {
  EXPECT_EQ(brick_accel_names(), (std::vector<std::string>{"embree", "bvh", "kdtree", "bsp", "grid", "hgrid",
                                                           "octree", "quadtree", "reference", "auto"}));
  auto builder = make_brick_builder("embree", {});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_EQ((*builder)->name(), "embree");
  EXPECT_FALSE(embree_config(**builder).robust);
  EXPECT_EQ(embree_config(**builder).quality, EmbreeQuality::kMedium);
  EXPECT_LT((*builder)->reserve_bytes(1000), (*builder)->reserve_bytes(2000));
}

TEST(BrickAccelFactory, OptionsAreParsed) {
  auto builder = make_brick_builder("embree", {{"robust", "1"}, {"quality", "low"}});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_TRUE(embree_config(**builder).robust);
  EXPECT_EQ(embree_config(**builder).quality, EmbreeQuality::kLow);
  builder = make_brick_builder("embree", {{"robust", "0"}, {"quality", "high"}});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_FALSE(embree_config(**builder).robust);
  EXPECT_EQ(embree_config(**builder).quality, EmbreeQuality::kHigh);
  builder = make_brick_builder("embree", {{"quality", "medium"}});
  ASSERT_TRUE(builder.ok());
  EXPECT_EQ(embree_config(**builder).quality, EmbreeQuality::kMedium);
}

TEST(BrickAccelFactory, UnknownNameListsKnownOnes) {
  auto builder = make_brick_builder("optix", {});
  ASSERT_FALSE(builder.ok());
  EXPECT_EQ(builder.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(contains(builder.status().message(), "'optix'")) << builder.status().message();
  EXPECT_TRUE(contains(builder.status().message(), "embree")) << builder.status().message();
}

TEST(BrickAccelFactory, BadOptionsAreNamed) {
  const std::vector<std::pair<BrickAccelOptions, std::vector<std::string>>> cases = {
      {{{"fast", "1"}}, {"'fast'", "robust", "quality"}},
      {{{"robust", "2"}}, {"robust", "'2'"}},
      {{{"robust", "true"}}, {"robust", "'true'"}},
      {{{"robust", ""}}, {"robust", "''"}},
      {{{"quality", "ultra"}}, {"quality", "'ultra'", "low, medium or high"}},
      {{{"quality", "High"}}, {"quality", "'High'"}},
      {{{"quality", "high"}, {"Robust", "1"}}, {"'Robust'"}},
  };
  for (const auto& [options, parts] : cases) {
    auto builder = make_brick_builder("embree", options);
    ASSERT_FALSE(builder.ok());
    EXPECT_EQ(builder.status().code(), StatusCode::kInvalidArgument);
    for (const auto& part : parts) {
      EXPECT_TRUE(contains(builder.status().message(), part))
          << builder.status().message() << " lacks " << part;
    }
  }
}

const BvhBrickConfig& bvh_config(const BrickBuilder& builder) {
  return dynamic_cast<const BvhBrickBuilder&>(builder).config();
}

TEST(BrickAccelFactory, BvhDefaultsAndOptions) {
  auto builder = make_brick_builder("bvh", {});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_EQ((*builder)->name(), "bvh");
  EXPECT_EQ(bvh_config(**builder).triangle_test, TriangleTest::kWatertight);
  EXPECT_EQ(bvh_config(**builder).builder.bin_count, BinnedSahBuilder::Config{}.bin_count);
  EXPECT_LT((*builder)->reserve_bytes(1000), (*builder)->reserve_bytes(2000));
  for (const auto& [name, test] :
       {std::pair{"mt", TriangleTest::kMt}, std::pair{"watertight", TriangleTest::kWatertight},
        std::pair{"double", TriangleTest::kDouble}}) {
    builder = make_brick_builder("bvh", {{"triangle_test", name}});
    ASSERT_TRUE(builder.ok()) << builder.status().to_string();
    EXPECT_EQ(bvh_config(**builder).triangle_test, test);
  }
  builder = make_brick_builder(
      "bvh", {{"bins", "32"}, {"max_leaf_size", "2"}, {"traversal_cost", "0.5"}, {"intersection_cost", "2"}});
  ASSERT_TRUE(builder.ok()) << builder.status().to_string();
  EXPECT_EQ(bvh_config(**builder).builder.bin_count, 32u);
  EXPECT_EQ(bvh_config(**builder).builder.max_leaf_size, 2u);
  EXPECT_EQ(bvh_config(**builder).builder.traversal_cost, 0.5f);
  EXPECT_EQ(bvh_config(**builder).builder.intersection_cost, 2.0f);
}

TEST(BrickAccelFactory, BadBvhOptionsAreNamed) {
  const std::vector<std::pair<BrickAccelOptions, std::vector<std::string>>> cases = {
      {{{"triangle_test", "fast"}}, {"triangle_test", "'fast'", "mt, watertight or double"}},
      {{{"triangle_test", ""}}, {"triangle_test", "''"}},
      {{{"triangle_test", "Watertight"}}, {"'Watertight'"}},
      {{{"robust", "1"}}, {"'robust'", "triangle_test"}},
      {{{"bins", "1"}}, {"bins", "2..256"}},
      {{{"bins", "16x"}}, {"bins", "'16x'"}},
      {{{"bins", "-4"}}, {"bins", "'-4'"}},
      {{{"max_leaf_size", "0"}}, {"max_leaf_size"}},
      {{{"max_leaf_size", ""}}, {"max_leaf_size", "''"}},
      {{{"traversal_cost", "nan"}}, {"traversal_cost", "'nan'"}},
      {{{"intersection_cost", "-1"}}, {"intersection_cost"}},
  };
  for (const auto& [options, parts] : cases) {
    auto builder = make_brick_builder("bvh", options);
    ASSERT_FALSE(builder.ok()) << options.begin()->first << "=" << options.begin()->second;
    EXPECT_EQ(builder.status().code(), StatusCode::kInvalidArgument);
    for (const auto& part : parts) {
      EXPECT_TRUE(contains(builder.status().message(), part))
          << builder.status().message() << " lacks " << part;
    }
  }
}

// Builds through the interface from several threads at once (the Embree part
// is serialised); every brick's bytes are back with Embree once released.
TEST(BrickAccelFactory, BuildsConcurrentlyThroughTheInterface) {
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  const int64_t live_before = (*device)->live_bytes();
  auto builder = make_brick_builder("embree", {});
  ASSERT_TRUE(builder.ok());
  const BrickData sphere = accel_test::load_brick_from("gen:sphere?level=5");
  constexpr int kThreads = 4;
  std::vector<std::unique_ptr<BrickAccel>> accels(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int round = 0; round < 3; ++round) {
        BrickData copy = sphere;
        copy.brick_id = static_cast<uint32_t>(t);
        auto accel = (*builder)->build(std::move(copy));
        ASSERT_TRUE(accel.ok()) << accel.status().to_string();
        accels[t] = std::move(accel).value();
      }
    });
  }
  for (auto& th : threads) th.join();
  for (const auto& accel : accels) {
    ASSERT_NE(accel, nullptr);
    EXPECT_EQ(accel->triangle_count(), sphere.triangles.size());
    EXPECT_EQ(accel->memory_bytes(), accels[0]->memory_bytes());
    EXPECT_LE(accel->memory_bytes(), (*builder)->reserve_bytes(accel->triangle_count()));
    EXPECT_GT(accel->build_seconds(), 0.0);
  }
  accels.clear();
  EXPECT_EQ((*device)->live_bytes(), live_before);

  BrickData bad = sphere;
  bad.ids.pop_back();
  auto failed = (*builder)->build(std::move(bad));
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
