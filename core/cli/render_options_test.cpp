// The text forms of render's camera options: what parses, and errors that
// name the option and echo the value.
#include "core/cli/render_options.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(RenderOptionsTest, ParsesVectors) {
  auto v = parse_vec3_option("--eye", "0,-2.5,1e3");
  ASSERT_TRUE(v.ok()) << v.status().to_string();
  EXPECT_EQ(*v, (Vec3d{0, -2.5, 1000}));
  // Non-finite values parse here; the camera refuses them naming the option.
  auto nan = parse_vec3_option("--up", "nan,0,inf");
  ASSERT_TRUE(nan.ok());
  EXPECT_TRUE(std::isnan(nan->x));
  EXPECT_TRUE(std::isinf(nan->z));
}

TEST(RenderOptionsTest, RefusesMalformedVectors) {
  for (const std::string text :
       {"", "1,2", "1,2,3,4", "1,,3", "1, 2, 3", "a,b,c", "1;2;3", "1,2,3,", "+1,2,3"}) {
    auto v = parse_vec3_option("--center", text);
    ASSERT_FALSE(v.ok()) << text;
    EXPECT_EQ(v.status().message(), "--center '" + text + "': expected three numbers X,Y,Z (e.g. 0,-2.5,10)");
  }
}

TEST(RenderOptionsTest, ParsesSizes) {
  auto s = parse_size_option("640x480");
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->width, 640u);
  EXPECT_EQ(s->height, 480u);
  s = parse_size_option("1X16384");
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->height, 16384u);
}

TEST(RenderOptionsTest, RefusesBadSizes) {
  for (const std::string text : {"", "640", "640x", "x480", "640x480x3", "-640x480", "6.5x4", "640 x 480"}) {
    auto s = parse_size_option(text);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_EQ(s.status().message(), "--size '" + text + "': expected WIDTHxHEIGHT in pixels (e.g. 640x480)");
  }
  for (const std::string text : {"0x480", "640x0", "16385x2", "99999999999x2"}) {
    auto s = parse_size_option(text);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_NE(s.status().message().find("width and height must be 1 to 16384 pixels"), std::string::npos)
        << s.status().message();
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
