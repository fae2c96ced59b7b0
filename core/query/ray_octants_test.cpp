// RayOctants: eight consecutive rays make a packet exactly when at least two
// are valid and the valid ones share a direction octant (signed zeros count
// by their sign, as std::signbit says); invalid rays are holes.
#include "core/query/ray_octants.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// The packet lanes the rule above gives, lane by lane.
uint32_t expected_lanes(const Ray* rays, const bool* valid) {
  uint32_t lanes = 0;
  int octant = -1;
  for (uint32_t j = 0; j < 8; ++j) {
    if (!valid[j]) continue;
    const Vec3f& d = rays[j].direction;
    const int o = int(std::signbit(d.x)) | int(std::signbit(d.y)) << 1 | int(std::signbit(d.z)) << 2;
    if (octant >= 0 && o != octant) return 0;
    octant = o;
    lanes |= 1u << j;
  }
  return __builtin_popcount(lanes) < 2 ? 0 : lanes;
}

TEST(RayOctants, PacketLanesFollowTheOctantRuleWithHoles) {
  constexpr std::size_t kRays = 64;
  std::mt19937 rng(9);
  const float values[] = {1.0f, -1.0f, 0.0f, -0.0f, 0.5f, -2.0f};
  std::size_t packets = 0;
  for (int round = 0; round < 2000; ++round) {
    Ray rays[kRays];
    bool valid[kRays];
    RayOctants<kRays> octants;
    // Few distinct directions, so that shared octants are common.
    const int kinds = 1 + round % 4;
    for (std::size_t k = 0; k < kRays; ++k) {
      const int kind = int(rng() % kinds);
      rays[k].direction = {values[(kind + k % 2 * (round % 3 == 0)) % 6], values[(kind * 3) % 6],
                           values[(kind * 5 + 1) % 6]};
      valid[k] = rng() % 5 != 0;
      if (valid[k]) {
        octants.set(k, rays[k]);
      } else {
        octants.set_invalid(k);
      }
    }
    for (std::size_t k = 0; k + 8 <= kRays; ++k) {
      const uint32_t want = expected_lanes(rays + k, valid + k);
      ASSERT_EQ(octants.packet_lanes(k), want) << "round " << round << " ray " << k;
      packets += want != 0;
    }
  }
  EXPECT_GT(packets, 1000u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
