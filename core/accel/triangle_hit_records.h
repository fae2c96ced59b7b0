// hit_records_for: what a hit on each triangle reports besides t, u, v (the
// unit normal and the user's ids), for the structures that keep a brick's
// triangles in input order (the kd-tree, the BSP, the octree, the grid).
//
// Thread-safety: a pure function.
#pragma once

#include <span>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"

namespace outcore {

// records[k] belongs to triangles[k]; ids has one entry per triangle.
std::vector<BvhHitRecord> hit_records_for(std::span<const Triangle> triangles,
                                          std::span<const TriangleId> ids);

}  // namespace outcore
