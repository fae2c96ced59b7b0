// BrickData: one brick's triangles in memory as loaded from the store —
// positions exactly as packed, and the user's (geometry_id, primitive_id) for
// every triangle, so hits are reported in the user's ids, never brick-local ones.
//
// Thread-safety: plain value.
#pragma once

#include <cstdint>
#include <vector>

#include "core/geometry/triangle.h"

namespace outcore {

struct TriangleId {
  uint32_t geometry_id;
  uint32_t primitive_id;
  bool operator==(const TriangleId&) const = default;
};
static_assert(sizeof(TriangleId) == 8);

struct BrickData {
  uint32_t brick_id = 0;
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;  // ids[i] names triangles[i]

  uint64_t memory_bytes() const {
    return triangles.capacity() * sizeof(Triangle) + ids.capacity() * sizeof(TriangleId);
  }
};

}  // namespace outcore
