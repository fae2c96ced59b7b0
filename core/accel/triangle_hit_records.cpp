#include "core/accel/triangle_hit_records.h"

#include <cassert>

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

}  // namespace outcore
