#include "core/util/line_plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

int count_color(const RgbImage& image, uint32_t color) {
  int n = 0;
  for (uint32_t y = 0; y < image.height; ++y)
    for (uint32_t x = 0; x < image.width; ++x)
      n += image.get(static_cast<int>(x), static_cast<int>(y)) == color;
  return n;
}

TEST(LinePlotTest, DrawsEverySeriesInItsColourWithLegendAndText) {
  std::vector<PlotSeries> series(3);
  series[0] = {"lru", {1, 2, 4, 8}, {0.9, 0.6, 0.3, 0.1}, false};
  series[1] = {"arc", {1, 2, 4, 8}, {0.8, 0.5, 0.25, 0.1}, false};
  series[2] = {"opt", {1, 2, 4, 8}, {0.6, 0.3, 0.15, 0.1}, true};
  LinePlotConfig config;
  config.title = "miss ratio";
  config.x_label = "budget (MiB)";
  config.y_label = "miss ratio";
  config.log_x = true;
  auto image = render_line_plot(series, config);
  ASSERT_TRUE(image.ok()) << image.status().to_string();
  EXPECT_EQ(image->width, config.width);
  EXPECT_EQ(image->height, config.height);
  EXPECT_EQ(image->pixels.size(), std::size_t{config.width} * config.height * 3);
  EXPECT_GT(count_color(*image, plot_series_color(0)), 300);
  EXPECT_GT(count_color(*image, plot_series_color(1)), 300);
  EXPECT_GT(count_color(*image, 0x000000), 500) << "dashed OPT, text";
  EXPECT_GT(count_color(*image, 0xffffff), static_cast<int>(config.width * config.height / 2))
      << "mostly background";
}

TEST(LinePlotTest, HigherValuesAreDrawnHigher) {
  // A single rising series: its leftmost coloured pixel is lower (larger y)
  // than its rightmost one.
  std::vector<PlotSeries> series = {{"up", {0, 1}, {0, 1}, false}};
  auto image = render_line_plot(series, {});
  ASSERT_TRUE(image.ok());
  const uint32_t color = plot_series_color(0);
  int left_x = 1 << 30, left_y = 0, right_x = -1, right_y = 0;
  for (uint32_t y = 0; y < image->height; ++y)
    for (uint32_t x = 0; x < image->width - 200; ++x) {  // not the legend
      if (image->get(static_cast<int>(x), static_cast<int>(y)) != color) continue;
      if (static_cast<int>(x) < left_x) left_x = static_cast<int>(x), left_y = static_cast<int>(y);
      if (static_cast<int>(x) > right_x) right_x = static_cast<int>(x), right_y = static_cast<int>(y);
    }
  ASSERT_LT(left_x, right_x);
  EXPECT_GT(left_y, right_y + 100);
}

TEST(LinePlotTest, RejectsBadInput) {
  EXPECT_FALSE(render_line_plot({}, {}).ok());
  std::vector<PlotSeries> mismatched = {{"a", {1, 2}, {1}, false}};
  EXPECT_FALSE(render_line_plot(mismatched, {}).ok());
  std::vector<PlotSeries> nan = {{"a", {1, 2}, {1, NAN}, false}};
  EXPECT_FALSE(render_line_plot(nan, {}).ok());
  std::vector<PlotSeries> zero = {{"a", {0, 2}, {1, 1}, false}};
  LinePlotConfig log;
  log.log_x = true;
  EXPECT_FALSE(render_line_plot(zero, log).ok());
  EXPECT_TRUE(render_line_plot(zero, {}).ok());
  LinePlotConfig tiny;
  tiny.width = 10;
  EXPECT_FALSE(render_line_plot(zero, tiny).ok());
  // One point, flat data: still a valid image.
  std::vector<PlotSeries> one = {{"a", {3}, {0.5}, false}};
  EXPECT_TRUE(render_line_plot(one, log).ok());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
