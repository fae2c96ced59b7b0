// hit_records_for: what a hit on each triangle reports besides t, u, v (the
// unit normal and the user's ids), for the structures that keep a brick's
// triangles in input order (the kd-tree, the BSP, the octree, the quadtree,
// the grids), and the check of their references against those triangles.
//
// Thread-safety: a pure function.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

// records[k] belongs to triangles[k]; ids has one entry per triangle.
std::vector<BvhHitRecord> hit_records_for(std::span<const Triangle> triangles,
                                          std::span<const TriangleId> ids);

// What every such structure's validate() checks first: records match
// triangles, and every reference names a triangle. `what` (the structure's
// name) prefixes errors.
Status validate_triangle_refs(const std::string& what, std::span<const uint32_t> refs,
                              std::span<const Triangle> triangles, std::span<const BvhHitRecord> records);

}  // namespace outcore
