// DynamicMesh: one mesh of the dynamic layer (core/dynamic/), its triangles
// in an 8-wide BVH (the bvh brick's WideBvh, watertight test) that follows
// its vertices: a vertex update refits the tree (same shape, boxes
// recomputed bottom-up) and builds it afresh only when the refitted tree's
// surface-area cost exceeds kRebuildRatio x the cost it had when last built
// (the cost is relative to the root box, so a mesh that moves or scales as a
// whole keeps it; one that scrambles raises it).
//
// Every triangle stays in the tree, degenerate ones included: a triangle
// that is flat now may not be after the next update. The watertight test
// never hits a triangle of zero area (it is parallel to every ray's plane in
// double), so answers equal those of a fresh build of the same vertices.
// Primitive ids are the triangles' order as given; the geometry id in the
// tree is 0, replaced by the instance's when a hit is reported.
//
// A DynamicMesh is immutable once made: an update makes a new one (sharing
// the topology), so queries holding the old version keep it whole.
//
// Thread-safety: immutable; any thread.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/accel/bvh/wide_bvh.h"
#include "core/geometry/aabb.h"
#include "core/geometry/vec3.h"
#include "core/util/status.h"

namespace outcore {

// Triangles as vertex indices; fixed for the mesh's life.
struct MeshTopology {
  std::vector<std::array<uint32_t, 3>> triangles;
  uint32_t vertex_count = 0;
};

class DynamicMesh {
 public:
  static constexpr double kRebuildRatio = 1.5;
  static constexpr uint64_t kMaxTriangles = 0xfffffffeu;

  // vertices: x, y, z per vertex; triangles: three vertex indices each.
  // INVALID_ARGUMENT naming `what` and the first bad element: lengths not
  // multiples of 3, no triangles, a vertex not finite, an index beyond the
  // vertices.
  static Expected<std::shared_ptr<const DynamicMesh>> create(std::span<const float> vertices,
                                                             std::span<const uint32_t> triangles,
                                                             const std::string& what);
  // The same topology at new vertex positions: refitted, or rebuilt when
  // the refit degraded it (rebuilt()). INVALID_ARGUMENT when the vertex
  // count differs from the mesh's (topology is fixed) or one is not finite.
  Expected<std::shared_ptr<const DynamicMesh>> moved(std::span<const float> vertices,
                                                     const std::string& what) const;
  // The same vertices in a freshly built tree (what tests compare a refit with).
  std::shared_ptr<const DynamicMesh> rebuilt_fresh() const;

  WideBvhView view() const { return tree_.view(); }
  Aabb bounds() const { return bounds_; }
  uint32_t triangle_count() const { return static_cast<uint32_t>(topology_->triangles.size()); }
  uint32_t vertex_count() const { return topology_->vertex_count; }
  std::span<const Vec3f> vertices() const { return vertices_; }
  const std::shared_ptr<const MeshTopology>& topology() const { return topology_; }
  // The tree's surface-area cost now and when it was last built.
  double sah_cost() const { return sah_cost_; }
  double built_sah_cost() const { return built_sah_cost_; }
  // Whether this version came from a build (create, or a refit that
  // degraded past kRebuildRatio) rather than a refit.
  bool rebuilt() const { return rebuilt_; }
  uint64_t memory_bytes() const;

 private:
  DynamicMesh() = default;
  static std::shared_ptr<const DynamicMesh> build(std::shared_ptr<const MeshTopology> topology,
                                                  std::vector<Vec3f> vertices);

  std::shared_ptr<const MeshTopology> topology_;
  std::vector<Vec3f> vertices_;
  WideBvh tree_;
  Aabb bounds_;
  double sah_cost_ = 0;
  double built_sah_cost_ = 0;
  bool rebuilt_ = true;
};

}  // namespace outcore
