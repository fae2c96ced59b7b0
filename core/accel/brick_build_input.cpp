#include "core/accel/brick_build_input.h"

namespace outcore {

std::string brick_build_context(const BrickData& brick, std::string_view structure) {
  return "building brick " + std::to_string(brick.brick_id) + " (" + std::string(structure) + ")";
}

Status check_brick_build_input(const BrickData& brick, const std::string& context, uint64_t max_triangles) {
  const uint64_t n = brick.triangles.size();
  if (brick.ids.size() != n) {
    return invalid_argument(context + ": " + std::to_string(n) + " triangles but " +
                            std::to_string(brick.ids.size()) + " ids");
  }
  if (n > max_triangles) {
    return out_of_range(context + ": " + std::to_string(n) + " triangles, at most " +
                        std::to_string(max_triangles));
  }
  return Status::Ok();
}

void keep_usable_triangles(BrickData& brick) {
  uint64_t kept = 0;
  for (uint64_t k = 0; k < brick.triangles.size(); ++k) {
    const Triangle& tri = brick.triangles[k];
    if (!tri.is_finite() || tri.is_degenerate()) continue;
    if (kept != k) {
      brick.triangles[kept] = tri;
      brick.ids[kept] = brick.ids[k];
    }
    ++kept;
  }
  brick.triangles.resize(kept);
  brick.ids.resize(kept);
}

}  // namespace outcore
