// DynamicSnapshot: one version of the dynamic layer — its meshes, the live
// instances (a mesh placed by an affine transform, with a geometry id of
// its own) and a top-level 8-wide BVH over the instances' world boxes — and
// the ray queries over it. Immutable: DynamicScene (dynamic_scene.h) makes a
// new snapshot for every update, so a query that holds one sees exactly that
// version, never a mix.
//
// A ray walks the top level (boxes tested in double, widened by the slack
// of the ray's trip into an instance's frame), and at each instance it may
// hit, is taken into the instance's frame (AffineTransform::ray_to_object,
// same t) and traced through the mesh's tree with the watertight test; a hit
// gets the instance's geometry id and a world normal and is kept under
// hit_is_better's tie rule, so the answer does not depend on the order in
// which instances are visited, on the top level's shape, or on whether a
// tree was refitted or built.
//
// Thread-safety: immutable; intersect()/occluded() from any threads.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "core/accel/bvh/wide_bvh.h"
#include "core/dynamic/bkd_tree.h"
#include "core/dynamic/dynamic_mesh.h"
#include "core/geometry/affine_transform.h"
#include "core/ray/ray_types.h"

namespace outcore {

struct DynamicInstance {
  uint32_t geometry_id = 0;
  uint32_t mesh_id = 0;
  AffineTransform to_world;
  AffineTransform to_object;  // to_world's inverse
  Aabb world_box;
  // Relative slack of a world box test for a ray of this instance
  // (to_world's condition number x a few float ulps).
  double slack = 0;
};

// The structure over the instances: an 8-wide BVH (the default) or the
// seed's B-KD tree (bkd_tree.h); both refitted on updates, rebuilt past
// kTopLevelRebuildRatio x their cost when built. Answers are the same.
enum class DynamicTopLevel : uint8_t { kBvh, kBkd };
// Lower than a mesh's 1.5: a top level builds in about the time of a
// transform update (10,000 instances: ~2.5 ms), and a refitted one over
// instances that wander loses speed faster than a deforming mesh does
// (docs/BENCHMARKS.md, "Dynamic geometry").
inline constexpr double kTopLevelRebuildRatio = 1.1;

struct DynamicSnapshot {
  uint64_t version = 0;
  DynamicTopLevel top_kind = DynamicTopLevel::kBvh;
  std::vector<std::shared_ptr<const DynamicMesh>> meshes;  // by mesh id
  std::vector<DynamicInstance> instances;                  // live ones, by geometry id
  std::vector<WideBvhNode> top;                            // kBvh: leaf child = index into instances
  BkdTree bkd;                                             // kBkd
  double top_built_cost = 0;                               // the top level's cost when last built

  // For each ray: the closest dynamic hit within [tnear, min(tfar, hits[i].t)],
  // replacing hits[i] when hit_is_better says so (so hits may hold the
  // static scene's answers, merged under the same tie rule). Invalid rays
  // (ray_problem.h) are left as they are. Returns how many misses became hits.
  uint64_t intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
  // For each valid ray with occluded[i] == 0: 1 when it hits dynamic
  // geometry. Returns how many became 1.
  uint64_t occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

  // The instance with this geometry id, or nullptr.
  const DynamicInstance* find(uint32_t geometry_id) const;
  // The same in a snapshot being made (DynamicScene, before publishing).
  DynamicInstance* find(uint32_t geometry_id) {
    return const_cast<DynamicInstance*>(std::as_const(*this).find(geometry_id));
  }
  uint64_t triangle_count() const;  // over live instances
  uint64_t memory_bytes() const;    // meshes counted once
};

// Builds `snapshot.top` afresh over its instances' world boxes.
void build_dynamic_top_level(DynamicSnapshot& snapshot);
// Refits `snapshot.top` to its instances' world boxes (same instances in the
// same order); builds afresh when the refitted cost exceeds
// kTopLevelRebuildRatio x top_built_cost. Returns whether it rebuilt.
bool refit_dynamic_top_level(DynamicSnapshot& snapshot);

}  // namespace outcore
