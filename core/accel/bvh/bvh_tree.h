// BvhTree: a brick's bounding volume hierarchy in compact form — 32-byte
// nodes (box, then either the index of the first of two adjacent children or a
// range of triangles), the triangles reordered so that every leaf is one
// contiguous range, and per triangle what a hit reports besides t, u, v (the
// user's ids and the unit normal). Built by BinnedSahBuilder (binned_sah_builder.h),
// traversed by bvh_traversal.h; the tree itself knows neither.
//
// Serialised with cereal (save/load below; the arrays as raw little-endian
// blocks, for cereal's binary archives). A loaded tree is checked by validate()
// before use, so a corrupt or hostile file is an error, never a crash.
//
// Thread-safety: plain value; immutable trees may be read from many threads.
#pragma once

#include <cereal/cereal.hpp>

#include <algorithm>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// Deepest tree the fixed traversal stack supports; the builder never exceeds
// it (it falls back to median splits well before) and validate() checks it.
inline constexpr uint32_t kMaxBvhDepth = 64;

struct BvhNode {
  Aabb bounds;
  uint32_t index = 0;  // inner: first child (the second is index + 1); leaf: first triangle
  uint32_t count = 0;  // 0 for an inner node, else the leaf's triangle count

  bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32);

// What a hit on triangle k reports besides t, u, v.
struct BvhHitRecord {
  Vec3f normal;  // unit, normalize(cross(v1 - v0, v2 - v0)) in float64, rounded
  uint32_t geometry_id;
  uint32_t primitive_id;
};
static_assert(sizeof(BvhHitRecord) == 20);

struct BvhTree {
  std::vector<BvhNode> nodes;  // nodes[0] is the root; empty for a tree without triangles
  std::vector<Triangle> triangles;
  std::vector<BvhHitRecord> records;  // records[k] belongs to triangles[k]

  uint64_t memory_bytes() const {
    return nodes.capacity() * sizeof(BvhNode) + triangles.capacity() * sizeof(Triangle) +
           records.capacity() * sizeof(BvhHitRecord);
  }

  // Structural checks: children after their parent and in range, leaves
  // covering the triangles in range, depth <= kMaxBvhDepth, one record per
  // triangle. Boxes are not checked against their contents (that would cost
  // as much as a build); a wrong box can only lose hits, never crash.
  Status validate() const;

  template <class Archive>
  void save(Archive& ar) const {
    save_array(ar, nodes);
    save_array(ar, triangles);
    save_array(ar, records);
  }
  template <class Archive>
  void load(Archive& ar) {
    load_array(ar, nodes);
    load_array(ar, triangles);
    load_array(ar, records);
  }

 private:
  static constexpr uint64_t kMaxArrayElements = uint64_t{1} << 32;

  template <class Archive, class T>
  static void save_array(Archive& ar, const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    ar(cereal::make_size_tag(static_cast<cereal::size_type>(v.size())));
    ar(cereal::binary_data(v.data(), v.size() * sizeof(T)));
  }
  template <class Archive, class T>
  static void load_array(Archive& ar, std::vector<T>& v) {
    cereal::size_type size = 0;
    ar(cereal::make_size_tag(size));
    if (size > kMaxArrayElements)
      throw cereal::Exception("bvh: array of " + std::to_string(size) + " elements");
    // In chunks, so that a corrupt size fails at the end of the input instead
    // of allocating (and zero-filling) whatever the size claims.
    constexpr std::size_t kChunk = std::size_t{1} << 16;
    v.clear();
    while (v.size() < size) {
      const std::size_t begin = v.size();
      const std::size_t count = std::min<std::size_t>(kChunk, static_cast<std::size_t>(size) - begin);
      v.resize(begin + count);
      ar(cereal::binary_data(v.data() + begin, count * sizeof(T)));
    }
    v.shrink_to_fit();
  }
};

// Round trip through cereal's binary archive; deserialisation validates.
std::string serialize_bvh(const BvhTree& tree);
Expected<BvhTree> deserialize_bvh(const std::string& bytes);

}  // namespace outcore
