// The walks restricted to a part of the bricks (upper_part.h): every form
// (flat leaves, 4-wide, 8-wide) gives each ray the part's bricks, in the same
// order and with bitwise the same keys, as the whole hierarchy's walk with
// the other bricks dropped, and tests fewer boxes doing it; an empty part
// gives no brick at all.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "core/query/upper_walks.h"
#include "core/store/scene_store.h"
#include "core/util/cpu_features.h"
#include "tests/support/packed_scene.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Every brick the ray's segment enters, front to back, window by window.
std::vector<BrickKey> all_bricks(const UpperWalks& walks, bool use_avx, const Ray& ray, uint64_t& nodes) {
  std::vector<BrickKey> keys;
  const SlabRay slab(ray);
  BrickKey last{};
  for (;;) {
    std::array<BrickKey, 4> window;
    const uint32_t found = walks.next_window(use_avx, slab, ray.tnear, ray.tfar, last, window, nodes);
    for (uint32_t k = 0; k < found; ++k) keys.push_back(window[k]);
    if (found < window.size()) return keys;
    last = window[found - 1];
  }
}

void expect_restricted_walks_are_filtered_whole_walks(const std::string& input, uint32_t brick_triangles) {
  SCOPED_TRACE(input + ", bricks of " + std::to_string(brick_triangles));
  const auto scene = testing::pack_test_scene({input}, brick_triangles);
  auto store = SceneStore::open(scene->path);
  ASSERT_TRUE(store.ok());
  const UpperWalks whole((*store)->manifest().upper);
  const uint32_t bricks = (*store)->brick_count();
  std::vector<uint8_t> in_part(bricks, 0);
  for (uint32_t b = 0; b < bricks; b += 3) in_part[b] = 1;
  const UpperWalks part = whole.restricted_to(in_part);
  const UpperWalks none = whole.restricted_to(std::vector<uint8_t>(bricks, 0));
  const std::vector<Ray> rays = testing::make_test_rays(scene->bounds, 3000, 17);
  for (const bool use_avx : {false, cpu_has_avx()}) {
    uint64_t whole_nodes = 0, part_nodes = 0, none_nodes = 0;
    std::size_t part_keys = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      std::vector<BrickKey> expected;
      for (const BrickKey& key : all_bricks(whole, use_avx, rays[i], whole_nodes))
        if (in_part[key.brick]) expected.push_back(key);
      const std::vector<BrickKey> got = all_bricks(part, use_avx, rays[i], part_nodes);
      ASSERT_EQ(got.size(), expected.size()) << "ray " << i;
      for (std::size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].brick, expected[k].brick) << "ray " << i;
        EXPECT_EQ(std::memcmp(&got[k].entry, &expected[k].entry, sizeof(float)), 0) << "ray " << i;
      }
      part_keys += got.size();
      EXPECT_TRUE(all_bricks(none, use_avx, rays[i], none_nodes).empty());
    }
    EXPECT_GT(part_keys, rays.size() / 10);  // the rays do reach bricks of the part
    EXPECT_LT(part_nodes, whole_nodes) << (use_avx ? "8-wide" : "4-wide or flat");
  }
}

TEST(UpperPart, RestrictedWalksGiveThePartsBricksAsTheWholeWalkWithFewerBoxes) {
  expect_restricted_walks_are_filtered_whole_walks("gen:sphere?level=3", 300);   // flat leaves (<= 8 bricks)
  expect_restricted_walks_are_filtered_whole_walks("gen:sphere?level=5", 400);   // wide
  expect_restricted_walks_are_filtered_whole_walks("gen:city?copies=30", 2048);  // wide, flat bricks
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
