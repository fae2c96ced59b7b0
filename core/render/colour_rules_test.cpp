// The colour rules, value by value. The depth ramp's expected colours were
// computed with numpy 2 (the Python client's arithmetic) as
//   floor(numpy.interp(s, [0, .25, .5, .75, 1], stop_channel) + 0.5)
// and the id colours with a Python transcription of SplitMix64 on unbounded
// integers masked to 64 bits.
#include "core/render/colour_rules.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(ColourRulesTest, DepthRampMatchesNumpyInterpRoundedHalfAway) {
  const struct {
    double s;
    Rgb want;
  } cases[] = {
      {0.0, {68, 1, 84}},     {0.1, {64, 33, 106}},  {0.125, {64, 42, 112}}, {0.2, {61, 66, 128}},
      {0.25, {59, 82, 139}},  {0.3, {54, 95, 139}},  {0.6, {57, 167, 123}},  {0.7071, {84, 191, 105}},
      {0.99, {247, 230, 39}}, {1.0, {253, 231, 37}},
  };
  for (const auto& c : cases) {
    const Rgb got = depth_ramp(c.s);
    EXPECT_EQ(got, c.want) << "s " << c.s << ": got " << int{got.r} << "," << int{got.g} << "," << int{got.b};
  }
  // Outside [0, 1] (never from depth_colour) the ends hold.
  EXPECT_EQ(depth_ramp(-0.5), kDepthStops.front());
  EXPECT_EQ(depth_ramp(7.0), kDepthStops.back());
}

TEST(ColourRulesTest, DepthIsBrightNearDarkFarAndBrightWhenAllHitsAreAtOneDepth) {
  EXPECT_EQ(depth_colour(2.0f, 2.0, 10.0), kDepthStops.back());
  EXPECT_EQ(depth_colour(10.0f, 2.0, 10.0), kDepthStops.front());
  EXPECT_EQ(depth_colour(6.0f, 2.0, 10.0), kDepthStops[2]);
  EXPECT_EQ(depth_colour(3.0f, 3.0, 3.0), kDepthStops.back());
  // 1 - (t - tmin) / (tmax - tmin) = 0.875 for t = 2 + 1.
  EXPECT_EQ(depth_colour(3.0f, 2.0, 10.0), depth_ramp(0.875));
}

TEST(ColourRulesTest, NormalsMapMinusOneToOneOntoZeroTo255) {
  EXPECT_EQ(normal_colour({1, 0, -1}), (Rgb{255, 128, 0}));  // 127.5 rounds away from zero
  EXPECT_EQ(normal_colour({0, 1, 0}), (Rgb{128, 255, 128}));
  EXPECT_EQ(normal_colour({-0.6f, 0.8f, 0}), (Rgb{51, 230, 128}));
  // A normal a rounding step longer than 1 still clamps.
  EXPECT_EQ(normal_colour({1.0000001f, -1.0000001f, 0}), (Rgb{255, 0, 128}));
}

TEST(ColourRulesTest, IdColoursAreSplitMix64Bytes) {
  EXPECT_EQ(splitmix64(0), 0xe220a8397b1dcdafull);  // SplitMix64's first output from seed 0
  EXPECT_EQ(splitmix64(1), 0x910a2dec89025cc1ull);
  EXPECT_EQ(id_colour(0), (Rgb{239, 77, 93}));
  EXPECT_EQ(id_colour(1), (Rgb{65, 156, 66}));
  EXPECT_EQ(id_colour(2), (Rgb{78, 150, 215}));
  EXPECT_EQ(id_colour(7), (Rgb{87, 77, 114}));
  EXPECT_EQ(id_colour(4294967294u), (Rgb{98, 250, 127}));
  for (uint32_t id = 0; id < 1000; ++id) {
    const Rgb c = id_colour(id);
    EXPECT_GE(std::min({c.r, c.g, c.b}), 64) << id;  // never mistaken for a miss
  }
}

TEST(ColourRulesTest, ModeNames) {
  for (RenderMode mode : {RenderMode::kDepth, RenderMode::kNormals, RenderMode::kIds}) {
    auto parsed = render_mode_from_name(render_mode_name(mode));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, mode);
  }
  auto bad = render_mode_from_name("colour");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "--mode 'colour': must be depth, normals or ids");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
