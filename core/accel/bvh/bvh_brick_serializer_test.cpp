// BvhBrickSerializer: a saved and reloaded bvh brick answers bitwise as the
// built one (every triangle test, models and generator scenes, degenerate
// triangles), reports the same memory and triangle count, and a malformed
// payload is an error, never a crash. Structure keys differ exactly when the
// config does.
#include "core/accel/bvh/bvh_brick_serializer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstring>
#include <memory>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::load_brick_from;

// Enough rays to hit every part of these small bricks; few enough for ASan.
constexpr std::size_t kRays = 1500;

BvhBrickConfig config_of(TriangleTest test) {
  BvhBrickConfig config;
  config.triangle_test = test;
  return config;
}

std::unique_ptr<BvhBrickAccel> build(BrickData brick, const BvhBrickConfig& config) {
  auto accel = BvhBrickAccel::build(std::move(brick), config);
  EXPECT_TRUE(accel.ok()) << accel.status().to_string();
  return std::move(accel).value();
}

std::string save(const BvhBrickSerializer& serializer, const BrickAccel& accel) {
  std::ostringstream out;
  const Status saved = serializer.save(accel, out);
  EXPECT_TRUE(saved.ok()) << saved.to_string();
  return std::move(out).str();
}

// Bytes at a chosen offset from a 64-byte boundary, owned by a shared_ptr as
// a mapped file would be.
class AlignedBytes {
 public:
  AlignedBytes(const std::string& bytes, std::size_t misalign)
      : storage_(bytes.size() + 128),
        offset_(64 - reinterpret_cast<uintptr_t>(storage_.data()) % 64 + misalign) {
    std::memcpy(storage_.data() + offset_, bytes.data(), bytes.size());
    size_ = bytes.size();
  }
  std::span<const char> bytes() const { return {storage_.data() + offset_, size_}; }

 private:
  std::vector<char> storage_;
  std::size_t offset_;
  std::size_t size_ = 0;
};

SerializedBrick unowned(std::string_view bytes) {
  return SerializedBrick{bytes, nullptr, false};
}

std::shared_ptr<const AlignedBytes> aligned_copy(const std::string& bytes) {
  return std::make_shared<const AlignedBytes>(bytes, 0);
}

std::vector<Ray> rays_for(const BrickData& brick, uint64_t seed) {
  const Aabb b = accel_test::bounds_of(brick);
  auto rays = accel_test::rays_from_outside(b, kRays / 2, seed);
  const auto inside = accel_test::rays_from_inside(b, kRays - kRays / 2, seed + 1);
  rays.insert(rays.end(), inside.begin(), inside.end());
  for (std::size_t i = 0; i < rays.size(); i += 5) rays[i].tfar = 0.3f * length(b.extent());
  return rays;
}

void expect_same_answers(const BrickAccel& built, const BrickAccel& loaded, const std::vector<Ray>& rays,
                         const std::string& what) {
  std::vector<Hit> a(rays.size()), b(rays.size());
  built.intersect(all_ids(rays.size()), rays.data(), a.data());
  loaded.intersect(all_ids(rays.size()), rays.data(), b.data());
  std::size_t hits = 0;
  for (const Hit& h : a) hits += h.is_hit();
  EXPECT_GT(hits, rays.size() / 100) << what << ": the rays should hit something";
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)), 0) << what;
  std::vector<uint8_t> oa(rays.size(), 0), ob(rays.size(), 0);
  built.occluded(all_ids(rays.size()), rays.data(), oa.data());
  loaded.occluded(all_ids(rays.size()), rays.data(), ob.data());
  EXPECT_EQ(oa, ob) << what;
}

TEST(BvhBrickSerializer, RoundTripAnswersBitwiseAndKeepsTheBytes) {
  const std::vector<std::pair<std::string, BrickData>> bricks = [] {
    std::vector<std::pair<std::string, BrickData>> out;
    out.emplace_back("bunny", load_brick_from(accel_test::bunny_path()));
    out.emplace_back("torus", load_brick_from("gen:torus?nu=48&nv=24"));
    out.emplace_back("sphere", load_brick_from("gen:sphere?level=4"));
    out.emplace_back("degenerate-heavy", accel_test::degenerate_heavy(3000, 7));
    return out;
  }();
  for (const auto& [name, brick] : bricks) {
    for (const TriangleTest test : kAllTriangleTests) {
      const std::string what = name + " " + std::string(triangle_test_name(test));
      const BvhBrickSerializer serializer(config_of(test));
      BrickData copy = brick;
      copy.brick_id = 17;
      const auto built = build(std::move(copy), config_of(test));
      const std::string payload = save(serializer, *built);
      auto loaded = serializer.load(unowned(payload), 17, built->triangle_count());
      ASSERT_TRUE(loaded.ok()) << what << ": " << loaded.status().to_string();
      const auto& bvh = dynamic_cast<const BvhBrickAccel&>(**loaded);
      EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes()) << what;
      EXPECT_EQ((*loaded)->triangle_count(), built->triangle_count()) << what;
      EXPECT_EQ(bvh.brick_id(), 17u) << what;
      EXPECT_EQ(bvh.triangle_test(), test) << what;
      EXPECT_EQ(bvh.view().nodes.size(), built->view().nodes.size()) << what;
      EXPECT_FALSE(bvh.in_place()) << what << ": bytes without an owner are copied";
      expect_same_answers(*built, **loaded, rays_for(brick, 99), what);
    }
  }
}

TEST(BvhBrickSerializer, EmptyBrickRoundTrips) {
  const BvhBrickSerializer serializer(config_of(TriangleTest::kWatertight));
  const auto built = build(BrickData{}, config_of(TriangleTest::kWatertight));
  auto loaded = serializer.load(unowned(save(serializer, *built)), 0, 0);
  ASSERT_TRUE(loaded.ok()) << loaded.status().to_string();
  EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes());
}

TEST(BvhBrickSerializer, MalformedPayloadsAreErrorsNotCrashes) {
  const BrickData brick = load_brick_from("gen:sphere?level=2");
  const BvhBrickSerializer serializer(config_of(TriangleTest::kWatertight));
  const auto built = build(brick, config_of(TriangleTest::kWatertight));
  const std::string payload = save(serializer, *built);
  const uint32_t n = built->triangle_count();
  for (const std::size_t cut :
       {std::size_t{0}, std::size_t{1}, std::size_t{9}, payload.size() / 2, payload.size() - 1}) {
    EXPECT_FALSE(serializer.load(unowned(std::string_view(payload).substr(0, cut)), 0, n).ok())
        << "cut at " << cut;
  }
  EXPECT_FALSE(serializer.load(unowned(payload + "x"), 0, n).ok()) << "trailing bytes";
  EXPECT_FALSE(serializer.load(unowned(payload), 0, n / 2).ok())
      << "more packets than the brick's triangles fill";
  std::string huge = payload;
  const uint64_t claimed = uint64_t{1} << 31;  // a node count far beyond the input
  std::memcpy(huge.data() + 8, &claimed, sizeof(claimed));
  EXPECT_FALSE(serializer.load(unowned(huge), 0, n).ok()) << "a count beyond the bytes";
  // A payload saved with another triangle test.
  const BvhBrickSerializer mt(config_of(TriangleTest::kMt));
  const std::string mt_payload = save(mt, *build(brick, config_of(TriangleTest::kMt)));
  auto wrong = serializer.load(unowned(mt_payload), 0, n);
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("triangle test"), std::string::npos) << wrong.status().message();
  // Saving a brick of another config is refused.
  std::ostringstream out;
  EXPECT_FALSE(serializer.save(*build(brick, config_of(TriangleTest::kMt)), out).ok());
  // A structurally broken tree behind a well-formed archive.
  std::string broken = payload;
  // The 64-byte header, then nodes[0]: every child made an inner node that is the root itself.
  const uint32_t self[kWideBvhWidth] = {};
  std::memcpy(broken.data() + 64 + offsetof(WideBvhNode, child), self, sizeof(self));
  broken[64 + offsetof(WideBvhNode, inner_mask)] = static_cast<char>(0xff);
  broken[64 + offsetof(WideBvhNode, leaf_mask)] = 0;
  EXPECT_FALSE(serializer.load(unowned(broken), 0, n).ok());
  // In place too, unless the caller vouches for the bytes.
  const auto owned = aligned_copy(broken);
  EXPECT_FALSE(serializer.load({owned->bytes(), owned, false}, 0, n).ok());
}

TEST(BvhBrickSerializer, AlignedOwnedPayloadsAreUsedInPlace) {
  const BrickData brick = load_brick_from("gen:torus?nu=48&nv=24");
  for (const TriangleTest test : kAllTriangleTests) {
    const std::string what(triangle_test_name(test));
    const BvhBrickSerializer serializer(config_of(test));
    const auto built = build(brick, config_of(test));
    const auto owned = aligned_copy(save(serializer, *built));
    for (const bool known_good : {false, true}) {
      auto loaded = serializer.load({owned->bytes(), owned, known_good}, 0, built->triangle_count());
      ASSERT_TRUE(loaded.ok()) << what << ": " << loaded.status().to_string();
      const auto& bvh = dynamic_cast<const BvhBrickAccel&>(**loaded);
      EXPECT_TRUE(bvh.in_place()) << what;
      EXPECT_EQ(static_cast<const void*>(bvh.view().nodes.data()),
                static_cast<const void*>(owned->bytes().data() + 64))
          << what << ": the nodes are read where they lie";
      EXPECT_EQ((*loaded)->memory_bytes(), built->memory_bytes()) << what;
      expect_same_answers(*built, **loaded, rays_for(brick, 5), what);
    }
    // The accel keeps the bytes alive after everyone else lets go, and only
    // as long as it lives.
    {
      auto owner = aligned_copy(save(serializer, *built));
      auto loaded = serializer.load({owner->bytes(), owner, false}, 0, built->triangle_count());
      ASSERT_TRUE(loaded.ok());
      const std::weak_ptr<const AlignedBytes> watch = owner;
      owner.reset();
      EXPECT_FALSE(watch.expired()) << what;
      expect_same_answers(*built, **loaded, rays_for(brick, 7), what);
      loaded->reset();
      EXPECT_TRUE(watch.expired()) << what;
    }
    // Misaligned bytes with an owner are copied, not read in place.
    auto shifted = std::make_shared<AlignedBytes>(save(serializer, *built), 1);
    auto copied = serializer.load({shifted->bytes(), shifted, false}, 0, built->triangle_count());
    ASSERT_TRUE(copied.ok()) << what;
    EXPECT_FALSE(dynamic_cast<const BvhBrickAccel&>(**copied).in_place()) << what;
    expect_same_answers(*built, **copied, rays_for(brick, 6), what);
  }
}

TEST(BvhBrickSerializer, StructureKeysDifferExactlyWhenTheConfigDoes) {
  std::set<std::string> keys;
  for (const TriangleTest test : kAllTriangleTests)
    keys.insert(BvhBrickSerializer(config_of(test)).structure_key());
  BvhBrickConfig c = config_of(TriangleTest::kWatertight);
  c.builder.bin_count = 32;
  keys.insert(BvhBrickSerializer(c).structure_key());
  c = config_of(TriangleTest::kWatertight);
  c.builder.max_leaf_size = 4;
  keys.insert(BvhBrickSerializer(c).structure_key());
  c = config_of(TriangleTest::kWatertight);
  c.builder.traversal_cost = std::nextafter(1.0f, 2.0f);  // the smallest change still differs
  keys.insert(BvhBrickSerializer(c).structure_key());
  c = config_of(TriangleTest::kWatertight);
  c.builder.intersection_cost = 2.0f;
  keys.insert(BvhBrickSerializer(c).structure_key());
  EXPECT_EQ(keys.size(), 7u);
  EXPECT_EQ(BvhBrickSerializer(config_of(TriangleTest::kMt)).structure_key(),
            BvhBrickSerializer(config_of(TriangleTest::kMt)).structure_key());
  EXPECT_EQ(BvhBrickSerializer(BvhBrickConfig{}).structure_key().rfind("bvh/", 0), 0u);
}

TEST(BvhBrickSerializer, BuilderHasOneAndOtherStructuresNone) {
  auto bvh = make_brick_builder("bvh", {{"triangle_test", "mt"}});
  ASSERT_TRUE(bvh.ok());
  ASSERT_NE((*bvh)->serializer(), nullptr);
  EXPECT_NE((*bvh)->serializer()->structure_key().find("triangle_test=mt"), std::string::npos);
  for (const char* name : {"embree", "reference"}) {
    auto other = make_brick_builder(name, {});
    ASSERT_TRUE(other.ok()) << name;
    EXPECT_EQ((*other)->serializer(), nullptr) << name;
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
