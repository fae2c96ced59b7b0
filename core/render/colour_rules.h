// How `outcore render` turns one hit into one pixel, per mode. The same rules
// are the Python client's outcore.render, to the byte; change both together.
//
// - every mode: a ray that missed is black (0, 0, 0);
// - depth: s = 1 - (t - tmin) / (tmax - tmin) over the image's hits (0 when
//   tmax == tmin), near bright; the colour is s interpolated linearly
//   through five stops at s = 0, 0.25, 0.5, 0.75, 1 (a viridis-like ramp,
//   kDepthStops), in float64 as numpy.interp does, rounded half away from
//   zero and clamped to 0..255;
// - normals: channel c = round(255 * (n_c * 0.5 + 0.5)) of the hit's unit
//   geometric normal, in float64 from the float normal, rounded half away
//   from zero, clamped;
// - ids: z = splitmix64(geometry_id); r, g, b = 64 + (byte 0, 1, 2 of z) % 192
//   (a stable colour per input, never too dark to tell from a miss).
//
// Thread-safety: pure functions.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "core/geometry/vec3.h"
#include "core/util/status.h"

namespace outcore {

enum class RenderMode { kDepth, kNormals, kIds };

// "depth", "normals", "ids"; INVALID_ARGUMENT naming --mode and the value otherwise.
Expected<RenderMode> render_mode_from_name(const std::string& name);
const char* render_mode_name(RenderMode mode);

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
  constexpr bool operator==(const Rgb&) const = default;
};

inline constexpr Rgb kMissColour{0, 0, 0};
inline constexpr std::array<Rgb, 5> kDepthStops = {Rgb{68, 1, 84}, Rgb{59, 82, 139}, Rgb{33, 145, 140},
                                                   Rgb{94, 201, 98}, Rgb{253, 231, 37}};

// The ramp at s (clamped to [0, 1]; NaN gives the first stop).
Rgb depth_ramp(double s);
// The depth colour of a hit at t among hits spanning [tmin, tmax].
Rgb depth_colour(float t, double tmin, double tmax);
Rgb normal_colour(const Vec3f& normal);

// SplitMix64's output function applied to x + the golden gamma (one step of
// the generator seeded with x).
uint64_t splitmix64(uint64_t x);
Rgb id_colour(uint32_t geometry_id);

}  // namespace outcore
