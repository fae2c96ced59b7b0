#include "core/upper/upper_packet_traversal.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "core/upper/upper_hierarchy_builder.h"
#include "tests/support/grid_boxes.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Eight rays: from one pinhole through neighbouring pixels (coherent), or
// each its own (origins on grid planes, zero direction components, short
// segments), so lanes go separate ways.
std::array<Ray, 8> packet_rays(std::mt19937& rng, bool coherent) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::uniform_int_distribution<int> pick(0, 3);
  std::array<Ray, 8> rays;
  const Vec3f eye(8 * u(rng), 4 + 2 * u(rng), 8 * u(rng));
  const Vec3f look = Vec3f(2 * u(rng), 0, 2 * u(rng)) - eye;
  for (uint32_t lane = 0; lane < 8; ++lane) {
    Ray& r = rays[lane];
    if (coherent) {
      r.origin = eye;
      r.direction = look + Vec3f(0.01f * float(lane), 0.002f * float(lane % 3), 0);
      if (pick(rng) == 0) r.tfar = 3.0f;
      if (pick(rng) == 0) r.tnear = 0.5f;
    } else {
      r = testing::grid_ray(rng, 6, 0.25f);
    }
  }
  return rays;
}

// Every lane of the packet walk finds bitwise the window next_bricks_wide
// finds for that ray alone, for coherent and scattered lanes, any subset of
// lanes, windows of 4 and 2, hierarchies of 1 to 700 bricks.
template <std::size_t N>
void expect_packet_matches_single(const WideUpper& wide, const std::array<Ray, 8>& rays, uint32_t lanes) {
  SlabPacket packet;
  std::array<std::array<BrickKey, N>, 8> windows{};
  std::array<std::array<BrickKey, N>*, 8> window_of;
  for (uint32_t lane = 0; lane < 8; ++lane) {
    packet.set(lane, rays[lane], rays[lane].tnear, rays[lane].tfar);
    window_of[lane] = &windows[lane];
  }
  uint32_t found[8];
  uint64_t packet_nodes = 0;
  first_bricks_wide_packet(wide, packet, lanes, window_of.data(), found, packet_nodes);
  for (uint32_t lane = 0; lane < 8; ++lane) {
    if (!(lanes >> lane & 1u)) {
      EXPECT_EQ(found[lane], 0u);
      continue;
    }
    std::array<BrickKey, N> single{};
    uint64_t nodes = 0;
    const SlabRay slab(rays[lane]);
    const uint32_t expected =
        next_bricks_wide(wide, slab, rays[lane].tnear, rays[lane].tfar, BrickKey{}, single, nodes);
    ASSERT_EQ(found[lane], expected) << "lane " << lane;
    for (uint32_t k = 0; k < expected; ++k) {
      ASSERT_EQ(windows[lane][k].brick, single[k].brick) << "lane " << lane << " key " << k;
      ASSERT_EQ(std::memcmp(&windows[lane][k].entry, &single[k].entry, sizeof(float)), 0)
          << "lane " << lane << " key " << k << ": " << windows[lane][k].entry << " vs " << single[k].entry;
    }
  }
}

TEST(UpperPacketTraversal, EveryLaneFindsBitwiseTheWindowOfItsOwnWalk) {
  if (!cpu_has_avx()) GTEST_SKIP() << "no AVX: the lane-by-lane form is next_bricks_wide itself";
  std::mt19937 rng(31);
  for (const std::size_t n : {1, 2, 7, 40, 300, 700}) {
    const UpperHierarchy upper = build_upper_hierarchy(testing::grid_boxes(n, rng, 6, 0.25f));
    WideUpper wide;
    make_wide_upper(upper, wide);
    for (int p = 0; p < 600; ++p) {
      const auto rays = packet_rays(rng, p % 2 == 0);
      const uint32_t lanes = p % 3 == 0 ? 0xffu : std::uniform_int_distribution<uint32_t>(0, 255)(rng);
      expect_packet_matches_single<4>(wide, rays, lanes);
      expect_packet_matches_single<2>(wide, rays, lanes);
      if (HasFatalFailure()) return;
    }
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
