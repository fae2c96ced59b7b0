#include "core/upper/brick_bounds.h"

namespace outcore {

std::optional<BrickBoundKind> brick_bound_from_name(std::string_view name) {
  if (name == "aabb") return BrickBoundKind::kAabb;
  if (name == "sphere") return BrickBoundKind::kSphere;
  if (name == "obb") return BrickBoundKind::kObb;
  return std::nullopt;
}

std::string_view brick_bound_name(BrickBoundKind kind) {
  switch (kind) {
    case BrickBoundKind::kAabb: return "aabb";
    case BrickBoundKind::kSphere: return "sphere";
    case BrickBoundKind::kObb: return "obb";
  }
  return "?";
}

}  // namespace outcore
