// render_bands: the loop of `outcore render`, the same in process and against
// a server: the camera's rays are made a band of whole rows at a time (at
// most band_rays rays), traced by the caller's TraceRays (QueryEngine or the
// gRPC client: core/ never sees the client), and their hits coloured into a
// RenderImage. Bands bound the memory of a large image (32 bytes a ray and a
// hit each) while keeping batches large enough for the engine to reorder.
//
// Thread-safety: runs on the calling thread; `trace` may use others.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/render/colour_rules.h"
#include "core/render/pinhole_camera.h"
#include "core/util/status.h"

namespace outcore {

// Closest hits of `rays` into `hits` (same size).
using TraceRays = std::function<Status(std::span<const Ray> rays, std::span<Hit> hits)>;

// 4 Mi rays: 128 MiB of rays and as much of hits; an image up to 2048 x 2048
// is one batch.
inline constexpr uint64_t kDefaultBandRays = uint64_t{1} << 22;

struct RenderReport {
  uint64_t rays = 0;
  uint64_t hits = 0;
  uint32_t bands = 0;
  double trace_seconds = 0;  // inside `trace` only
};

// Called after each band with the rays traced so far.
using BandProgress = std::function<void(uint64_t rays_done, uint64_t rays_total)>;

// The image's RGB bytes (row 0 first). A trace error ends the render and is
// returned as it is.
Expected<std::vector<uint8_t>> render_bands(const PinholeRays& camera, RenderMode mode,
                                            const TraceRays& trace, RenderReport* report = nullptr,
                                            uint64_t band_rays = kDefaultBandRays,
                                            const BandProgress& progress = {});

}  // namespace outcore
