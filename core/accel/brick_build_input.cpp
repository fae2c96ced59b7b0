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

}  // namespace outcore
