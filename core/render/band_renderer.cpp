#include "core/render/band_renderer.h"

#include <algorithm>
#include <chrono>

#include "core/render/render_image.h"

namespace outcore {

Expected<std::vector<uint8_t>> render_bands(const PinholeRays& camera, RenderMode mode,
                                            const TraceRays& trace, RenderReport* report, uint64_t band_rays,
                                            const BandProgress& progress) {
  const uint32_t rows_per_band =
      static_cast<uint32_t>(std::clamp<uint64_t>(band_rays / camera.width(), 1, camera.height()));
  const std::size_t band_size = std::size_t{rows_per_band} * camera.width();
  std::vector<Ray> rays(band_size);
  std::vector<Hit> hits(band_size);
  RenderImage image(camera.width(), camera.height(), mode);
  RenderReport local;
  for (uint32_t row = 0; row < camera.height(); row += rows_per_band) {
    const std::size_t n = std::size_t{std::min(rows_per_band, camera.height() - row)} * camera.width();
    const std::span<Ray> band(rays.data(), n);
    const std::span<Hit> band_hits(hits.data(), n);
    camera.rows(row, band);
    const auto start = std::chrono::steady_clock::now();
    OUTCORE_RETURN_IF_ERROR(trace(band, band_hits));
    local.trace_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    image.add(uint64_t{row} * camera.width(), band_hits);
    local.rays += n;
    ++local.bands;
    if (progress) progress(local.rays, camera.pixel_count());
  }
  local.hits = image.hit_count();
  if (report != nullptr) *report = local;
  return image.rgb();
}

}  // namespace outcore
