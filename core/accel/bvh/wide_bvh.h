// WideBvh: the form of a brick's BVH that rays are traced through — 8 children
// per node, their boxes stored axis by axis so that one AVX operation tests
// all eight (or two SSE operations, four each), and the triangles in packets
// of eight, vertex coordinates in rows, so that one leaf is tested 4 or 8
// triangles at a time. Made from a binary BvhTree by WideBvhCollapser
// (wide_bvh_collapse.h); traced by wide_bvh_trace.h; the structure itself
// knows neither.
//
// Triangles live in "slots": slot s is lane s % 8 of packet s / 8. A leaf is a
// run of consecutive slots (first slot, count), so it may start mid-packet and
// run into the next; the collapser pads a little (bounded) so that most
// leaves of up to 8 triangles sit in one packet. Padding slots carry kInvalidId
// ids and zero vertices and belong to no leaf.
//
// WideBvh owns its arrays (a build); WideBvhView is what traversal reads, over
// a WideBvh or over a loaded subtree file in place. validate() checks a view
// that came from a file before it is used: a corrupt or hostile file is an
// error, never a crash.
//
// Thread-safety: plain values; immutable trees and views may be read from
// many threads.
#pragma once

#include <algorithm>
#include <cstdint>
#include <iterator>
#include <limits>
#include <span>
#include <vector>

#include "core/accel/bvh/bvh_tree.h"
#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

inline constexpr uint32_t kWideBvhWidth = 8;
inline constexpr uint32_t kPacketLanes = 8;

struct alignas(64) WideBvhNode {
  // Child k's box is lo[axis][k] .. hi[axis][k]; an empty slot has lo = +inf,
  // hi = -inf (no ray enters it) and is in neither mask.
  float lo[3][kWideBvhWidth];
  float hi[3][kWideBvhWidth];
  // Inner child: its node index (always after this node). Leaf: its first slot.
  uint32_t child[kWideBvhWidth];
  // Leaf: its triangle count (1..255); 0 for an inner child or an empty slot.
  uint8_t leaf_triangles[kWideBvhWidth];
  uint8_t inner_mask;  // bit k: child k is an inner node
  uint8_t leaf_mask;   // bit k: child k is a leaf
  uint8_t reserved[22];

  uint8_t child_mask() const { return static_cast<uint8_t>(inner_mask | leaf_mask); }

  // A node whose eight slots are empty (no child yet).
  static WideBvhNode empty() {
    WideBvhNode node{};
    for (int axis = 0; axis < 3; ++axis) {
      std::fill(std::begin(node.lo[axis]), std::end(node.lo[axis]), std::numeric_limits<float>::infinity());
      std::fill(std::begin(node.hi[axis]), std::end(node.hi[axis]), -std::numeric_limits<float>::infinity());
    }
    return node;
  }
  Aabb box(uint32_t k) const { return {{lo[0][k], lo[1][k], lo[2][k]}, {hi[0][k], hi[1][k], hi[2][k]}}; }
  void set_box(uint32_t k, const Aabb& box) {
    for (int axis = 0; axis < 3; ++axis) {
      lo[axis][k] = box.lo[axis];
      hi[axis][k] = box.hi[axis];
    }
  }
};
static_assert(sizeof(WideBvhNode) == 256);

struct alignas(32) TrianglePacket {
  // Row 3 * vertex + axis holds that coordinate of the 8 triangles.
  float coord[9][kPacketLanes];
  uint32_t geometry_id[kPacketLanes];
  uint32_t primitive_id[kPacketLanes];

  Triangle triangle(uint32_t lane) const {
    return {{coord[0][lane], coord[1][lane], coord[2][lane]},
            {coord[3][lane], coord[4][lane], coord[5][lane]},
            {coord[6][lane], coord[7][lane], coord[8][lane]}};
  }
};
static_assert(sizeof(TrianglePacket) == 352);

struct WideBvhView {
  std::span<const WideBvhNode> nodes;  // nodes[0] is the root; empty for a tree without triangles
  std::span<const TrianglePacket> packets;

  uint64_t slot_count() const { return uint64_t{packets.size()} * kPacketLanes; }
  // Structural checks: inner children after their parent and in range,
  // masks disjoint and only on used slots, leaves within the slots and not
  // overlapping, depth <= kMaxBvhDepth. Boxes and vertices are not checked
  // against each other: a wrong box can only lose hits, never crash.
  Status validate() const;
};

// Several trees traced as one (a resident brick set, bvh_brick_set.h): each
// ray walks the top level (wide_bvh_top_level.h), a wide BVH whose leaf
// children name trees, and searches the trees it enters nearest first,
// carrying its best hit from one to the next. A set of one tree may have no
// top level: the tree's root holds the same boxes.
struct WideBvhSetView {
  std::span<const WideBvhView> trees;
  std::span<const WideBvhNode> top;
};

struct WideBvh {
  std::vector<WideBvhNode> nodes;
  std::vector<TrianglePacket> packets;

  WideBvhView view() const { return {nodes, packets}; }
  static WideBvh copy_of(const WideBvhView& view) {
    return {{view.nodes.begin(), view.nodes.end()}, {view.packets.begin(), view.packets.end()}};
  }
  uint64_t memory_bytes() const {
    return nodes.capacity() * sizeof(WideBvhNode) + packets.capacity() * sizeof(TrianglePacket);
  }
};

}  // namespace outcore
