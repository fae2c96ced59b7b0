// BrickBounds: the bound tested before a ray is sent to a brick, chosen
// by `trace/serve --brick-bounds aabb|sphere|obb`. The upper hierarchy's leaf
// boxes (AABBs) are always tested (they sit in its wide nodes and cost
// nothing extra); sphere and obb add the brick's stored bounding sphere or
// oriented box (core/upper/bounding_sphere.h, oriented_box.h, fitted at
// pack time) as a second, tighter test. Both are conservative for the brick
// structure's triangle test (its hit rounding scale), so the choice never
// changes an answer, only how many brick visits find nothing
// (QueryStats::brick_visits_without_hit) and what the tests cost.
//
// Thread-safety: immutable after construction; may_hit() runs concurrently.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/upper/bounding_sphere.h"
#include "core/upper/oriented_box.h"

namespace outcore {

enum class BrickBoundKind : uint8_t { kAabb, kSphere, kObb };

inline constexpr char kDefaultBrickBounds[] = "aabb";

std::optional<BrickBoundKind> brick_bound_from_name(std::string_view name);
std::string_view brick_bound_name(BrickBoundKind kind);

class BrickBounds {
 public:
  // spheres[b] (sphere) or boxes[b] (obb) belongs to brick b (the
  // manifest's records); the other vector may be empty.
  BrickBounds(BrickBoundKind kind, std::vector<BoundingSphere> spheres, std::vector<OrientedBox> boxes,
              double rounding_scale)
      : kind_(kind),
        spheres_(std::move(spheres)),
        boxes_(std::move(boxes)),
        rounding_scale_(rounding_scale) {}

  BrickBoundKind kind() const { return kind_; }
  // Whether a test beyond the upper hierarchy's boxes is made at all.
  bool active() const { return kind_ != BrickBoundKind::kAabb; }
  // Whether [tmin, tmax] of `ray` may meet brick `brick`'s bound (always
  // true for aabb: the upper walk has tested the box).
  bool may_hit(uint32_t brick, const Ray& ray, float tmin, float tmax) const {
    switch (kind_) {
      case BrickBoundKind::kSphere: return spheres_[brick].may_hit(ray, tmin, tmax, rounding_scale_);
      case BrickBoundKind::kObb: return boxes_[brick].may_hit(ray, tmin, tmax, rounding_scale_);
      case BrickBoundKind::kAabb: break;
    }
    return true;
  }

 private:
  BrickBoundKind kind_;
  std::vector<BoundingSphere> spheres_;
  std::vector<OrientedBox> boxes_;
  double rounding_scale_;
};

}  // namespace outcore
