// DynamicScene: the dynamic layer beside the static out-of-core scene —
// meshes added at run time, instances of them (many instances share one
// mesh) placed by affine transforms, transforms and vertex positions updated
// from frame to frame (topology fixed), instances removed.
//
// Every successful change is atomic and publishes a new version
// (DynamicSnapshot, numbered from 1; version 0 is the empty layer): it is
// built beside the current one, sharing what did not change (meshes are
// immutable and shared), and swapped in whole; a failed change (a named
// error) leaves the scene exactly as it was. A query takes one snapshot —
// the latest, or a recent one by number (the last kKeptVersions are kept) —
// and sees exactly that version.
//
// Ids: meshes are numbered from 0 in order of addition; instances get
// geometry ids from first_geometry_id on (the static scene's geometry count,
// so dynamic ids continue after the static inputs'), never reused after a
// removal. Primitive ids are the mesh's own triangle order.
//
// Thread-safety: every member may be called from any thread; changes are
// serialised among themselves; readers never wait for a change in progress
// (they take the published snapshot under a short lock).
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <span>

#include "core/dynamic/dynamic_snapshot.h"
#include "core/util/status.h"

namespace outcore {

// "The latest version" where a version number is asked for.
inline constexpr uint64_t kLatestDynamicVersion = ~uint64_t{0};

// What an addition made: the new mesh id or geometry id, and the version
// that holds it.
struct DynamicAdded {
  uint32_t id = 0;
  uint64_t version = 0;
};

class DynamicScene {
 public:
  static constexpr std::size_t kKeptVersions = 16;

  explicit DynamicScene(uint32_t first_geometry_id = 0, DynamicTopLevel top_level = DynamicTopLevel::kBvh);

  // vertices: x, y, z each; triangles: 3 vertex indices each. Returns the mesh id.
  Expected<DynamicAdded> add_mesh(std::span<const float> vertices, std::span<const uint32_t> triangles);
  // transform: 12 numbers, a row-major 3x4 matrix (AffineTransform). Returns
  // the instance's geometry id.
  Expected<DynamicAdded> add_instance(uint32_t mesh_id, std::span<const double> transform);
  // 12 numbers per id, in the same order. Returns the new version. Every id
  // must be a live instance, each at most once.
  Expected<uint64_t> update_transforms(std::span<const uint32_t> geometry_ids,
                                       std::span<const double> transforms);
  // New positions for every vertex of the mesh (the same count). Returns the new version.
  Expected<uint64_t> update_vertices(uint32_t mesh_id, std::span<const float> vertices);
  // Removes an instance (its mesh stays, for other instances and new ones).
  // Returns the new version.
  Expected<uint64_t> remove(uint32_t geometry_id);

  std::shared_ptr<const DynamicSnapshot> latest() const;
  // NOT_FOUND when the version is newer than the latest or no longer kept.
  Expected<std::shared_ptr<const DynamicSnapshot>> at(uint64_t version) const;
  uint32_t first_geometry_id() const { return first_geometry_id_; }

  // What the layer's updates did, for statistics and tests.
  struct Counters {
    uint64_t mesh_refits = 0, mesh_rebuilds = 0, top_refits = 0, top_rebuilds = 0;
  };
  Counters counters() const;

 private:
  // Publishes `next` as the next version (under change_mutex_).
  uint64_t publish(std::shared_ptr<DynamicSnapshot> next);
  std::shared_ptr<DynamicSnapshot> copy_of_latest() const;
  Status check_mesh_id(uint32_t mesh_id, const DynamicSnapshot& s, const char* operation) const;

  const uint32_t first_geometry_id_;
  uint32_t next_geometry_id_;
  mutable std::mutex change_mutex_;                              // one change at a time
  mutable std::mutex publish_mutex_;                             // guards versions_ (readers hold it briefly)
  std::deque<std::shared_ptr<const DynamicSnapshot>> versions_;  // oldest first; back() the latest
  Counters counters_;
};

}  // namespace outcore
