// A small line-plot rasterizer: series of (x, y) points drawn as coloured
// polylines with point markers, axes with "nice" tick labels, axis labels, a
// title and a legend, into an RGB image (write it with png_writer.h). Made for
// `outcore cache-sim --png` (miss ratio against cache budget, one line per
// policy); readable, not fancy. Text uses a built-in 7×12 bitmap font
// (printable ASCII, rasterised from DejaVu Sans Mono 11 px).
//
// Thread-safety: functions of their arguments only.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

struct RgbImage {
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<uint8_t> pixels;  // rows top to bottom, 3 bytes per pixel

  void fill(uint8_t r, uint8_t g, uint8_t b);
  // Ignores points outside the image.
  void set(int x, int y, uint32_t rgb);
  uint32_t get(int x, int y) const;
};

struct PlotSeries {
  std::string name;
  std::vector<double> x;
  std::vector<double> y;
  bool dashed = false;  // e.g. a reference line such as OPT
};

struct LinePlotConfig {
  uint32_t width = 960;   // pixels, at least 320
  uint32_t height = 600;  // pixels, at least 240
  std::string title;
  std::string x_label;
  std::string y_label;
  bool log_x = false;  // logarithmic x axis (x must be > 0), ticks at the data's x values
  bool y_from_zero = true;
};

// Colour of series i (0xRRGGBB); dashed series are drawn black.
uint32_t plot_series_color(std::size_t i);

// INVALID_ARGUMENT for no series, x/y of different lengths, an empty series,
// non-finite values, x <= 0 with log_x, or a size below the minimum.
Expected<RgbImage> render_line_plot(std::span<const PlotSeries> series, const LinePlotConfig& config);

}  // namespace outcore
