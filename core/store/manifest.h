// Manifest: everything about a scene store except the triangles themselves —
// inputs, per-brick bounds / counts / byte ranges / checksums, and the fixed
// upper hierarchy. Serialised with cereal (portable binary) behind a header
// with a magic, the format version and a checksum (store_format.h).
//
// Thread-safety: plain value; read/write functions are reentrant.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/upper/bounding_sphere.h"
#include "core/upper/oriented_box.h"
#include "core/upper/upper_hierarchy.h"
#include "core/util/status.h"

namespace outcore {

struct InputRecord {
  std::string spec;  // what the user wrote: a path or a gen: spec
  uint64_t triangle_count = 0;
  uint64_t degenerate_count = 0;  // zero-area triangles (kept, ids stable)

  template <class Archive>
  void serialize(Archive& ar) {
    ar(spec, triangle_count, degenerate_count);
  }
};

struct BrickRecord {
  Aabb bounds;
  uint32_t triangle_count = 0;
  uint64_t offset = 0;      // into bricks.dat
  uint64_t size_bytes = 0;  // header + payload
  uint64_t checksum = 0;    // XXH3-64 of those bytes
  // Tighter bounds than the box, fitted at pack time around every vertex
  // (format version 2); trace/serve --brick-bounds picks the one tested.
  BoundingSphere sphere;
  OrientedBox obb;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(bounds.lo.x, bounds.lo.y, bounds.lo.z, bounds.hi.x, bounds.hi.y, bounds.hi.z, triangle_count, offset,
       size_bytes, checksum, sphere, obb);
  }
};

struct Manifest {
  uint32_t format_version = 0;
  std::string outcore_version;
  uint32_t brick_triangles_target = 0;  // --brick-tris at pack time
  Aabb bounds;
  uint64_t triangle_count = 0;
  uint64_t degenerate_count = 0;
  std::vector<InputRecord> inputs;
  std::vector<BrickRecord> bricks;
  UpperHierarchy upper;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(outcore_version, brick_triangles_target, bounds.lo.x, bounds.lo.y, bounds.lo.z, bounds.hi.x,
       bounds.hi.y, bounds.hi.z, triangle_count, degenerate_count, inputs, bricks, upper);
  }
};

// Writes header + payload to path (the caller makes the write atomic by writing
// into a temporary store directory).
Status write_manifest(const std::string& path, const Manifest& manifest);

// Reads and checks a manifest: magic, format version (FAILED_PRECONDITION on a
// mismatch, naming both versions), size and checksum (DATA_LOSS), and the
// internal consistency of bricks and the upper hierarchy.
Expected<Manifest> read_manifest(const std::string& path);

// Consistency checks shared by read_manifest and tests: counts add up, brick
// byte ranges are aligned and disjoint, the upper hierarchy's leaves are
// exactly the bricks, each once.
Status validate_manifest(const Manifest& manifest, const std::string& path);

}  // namespace outcore
