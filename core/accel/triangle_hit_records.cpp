#include "core/accel/triangle_hit_records.h"

#include <cassert>
#include <string>

namespace outcore {

std::vector<BvhHitRecord> hit_records_for(std::span<const Triangle> triangles,
                                          std::span<const TriangleId> ids) {
  assert(ids.size() == triangles.size());
  std::vector<BvhHitRecord> records;
  records.reserve(triangles.size());
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    records.push_back({triangles[k].unit_normal(), ids[k].geometry_id, ids[k].primitive_id});
  }
  return records;
}

Status validate_triangle_refs(const std::string& what, std::span<const uint32_t> refs,
                              std::span<const Triangle> triangles, std::span<const BvhHitRecord> records) {
  if (records.size() != triangles.size()) {
    return invalid_argument(what + ": " + std::to_string(records.size()) + " hit records for " +
                            std::to_string(triangles.size()) + " triangles");
  }
  for (std::size_t k = 0; k < refs.size(); ++k) {
    if (refs[k] >= triangles.size()) {
      return invalid_argument(what + ": reference " + std::to_string(k) + " names triangle " +
                              std::to_string(refs[k]) + " of " + std::to_string(triangles.size()));
    }
  }
  return Status::Ok();
}

}  // namespace outcore
