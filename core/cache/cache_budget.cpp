#include "core/cache/cache_budget.h"

#include <cstdio>

namespace outcore {

MinimumCacheBudget minimum_cache_budget(const Manifest& manifest, const BrickBuilder& builder) {
  MinimumCacheBudget minimum;
  for (uint32_t id = 0; id < manifest.bricks.size(); ++id) {
    const uint32_t triangles = manifest.bricks[id].triangle_count;
    const uint64_t reservation = builder.reserve_bytes(triangles);
    if (reservation > minimum.bytes) minimum = {reservation, id, triangles};
  }
  return minimum;
}

Status check_cache_budget(const Manifest& manifest, const BrickBuilder& builder, uint64_t budget_bytes) {
  const MinimumCacheBudget minimum = minimum_cache_budget(manifest, builder);
  if (minimum.bytes <= budget_bytes) return {};
  return invalid_argument(
      "the cache budget of " + describe_bytes(budget_bytes) + " is too small for this scene: brick " +
      std::to_string(minimum.brick_id) + " (" + std::to_string(minimum.triangle_count) +
      " triangles) needs up to " + describe_bytes(minimum.bytes) + " to build as '" + builder.name() +
      "'; the smallest workable budget is " + std::to_string(minimum.mib()) + " MiB (--cache-mb " +
      std::to_string(minimum.mib()) + "), or repack with smaller bricks (--brick-tris)");
}

std::string describe_bytes(uint64_t bytes) {
  char mib[64];
  std::snprintf(mib, sizeof(mib), "%.2f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return std::string(mib) + " (" + std::to_string(bytes) + " bytes)";
}

}  // namespace outcore
