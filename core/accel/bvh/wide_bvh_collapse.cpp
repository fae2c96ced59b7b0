#include "core/accel/bvh/wide_bvh_collapse.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <limits>
#include <vector>

#include "core/ray/ray_types.h"

namespace outcore {
namespace {

constexpr uint32_t kSmallSubtree = kPacketLanes;  // at most this many triangles: one leaf

// One child of the wide node being made: a binary subtree, or (a leaf) one
// or more binary subtrees whose triangles go into one run of slots.
struct Candidate {
  Aabb box;
  std::array<uint32_t, kPacketLanes> parts;  // binary nodes; a merged leaf has several
  uint32_t part_count = 1;
  uint32_t triangles = 0;
  bool leaf = false;
};

// Makes the wide tree twice from the same decisions: a counting pass (emit =
// false) that sizes the arrays exactly, then the pass that fills them.
class Collapse {
 public:
  Collapse(std::span<const BvhNode> nodes, std::span<const uint32_t> order,
           std::span<const Triangle> triangles, std::span<const TriangleId> ids)
      : nodes_(nodes), order_(order), triangles_(triangles), ids_(ids), subtree_(nodes.size()) {
    // Children come after their parent: one backward pass sums the counts.
    for (std::size_t k = nodes.size(); k-- > 0;) {
      const BvhNode& node = nodes[k];
      subtree_[k] = node.is_leaf() ? node.count : subtree_[node.index] + subtree_[node.index + 1];
    }
    const uint64_t n = triangles.size();
    padding_budget_ = std::min<uint64_t>(n / 4, std::numeric_limits<uint32_t>::max() - 16 - n);
  }

  uint64_t scratch_bytes() const { return subtree_.capacity() * sizeof(uint32_t); }

  // Counting pass; returns (node count, packet count).
  std::pair<uint64_t, uint64_t> count() {
    reset(nullptr);
    run();
    return {node_count_, (slot_ + kPacketLanes - 1) / kPacketLanes};
  }

  void fill(WideBvh& out) {
    reset(&out);
    run();
  }

 private:
  void reset(WideBvh* out) {
    out_ = out;
    node_count_ = 0;
    slot_ = 0;
    padding_ = 0;
  }

  void run() {
    if (nodes_.empty()) return;
    node_count_ = 1;
    make_node(0, 0);
  }

  bool small(uint32_t b) const { return nodes_[b].is_leaf() || subtree_[b] <= kSmallSubtree; }

  Candidate candidate(uint32_t b) const {
    Candidate c;
    c.box = nodes_[b].bounds;
    c.parts[0] = b;
    c.triangles = subtree_[b];
    c.leaf = small(b);
    return c;
  }

  // The children of the wide node over binary node b.
  uint32_t choose_children(uint32_t b, std::array<Candidate, kWideBvhWidth>& kids) const {
    uint32_t count = 0;
    if (small(b)) {
      kids[count++] = candidate(b);
      return count;
    }
    kids[count++] = candidate(nodes_[b].index);
    kids[count++] = candidate(nodes_[b].index + 1);
    while (count < kWideBvhWidth) {
      int widest = -1;
      for (uint32_t k = 0; k < count; ++k) {
        if (!kids[k].leaf && (widest < 0 || kids[k].box.half_area() > kids[widest].box.half_area())) {
          widest = static_cast<int>(k);
        }
      }
      if (widest < 0) break;
      const uint32_t opened = kids[widest].parts[0];
      kids[widest] = candidate(nodes_[opened].index);
      kids[count++] = candidate(nodes_[opened].index + 1);
    }
    merge_leaves(kids, count);
    return count;
  }

  // Greedy: merge the pair of leaves that saves the most area, while a pair
  // fits in one packet and saves any.
  static void merge_leaves(std::array<Candidate, kWideBvhWidth>& kids, uint32_t& count) {
    while (true) {
      int best_a = -1, best_b = -1;
      double best_saving = -1.0;
      for (uint32_t a = 0; a < count; ++a) {
        for (uint32_t b = a + 1; b < count; ++b) {
          if (!kids[a].leaf || !kids[b].leaf || kids[a].triangles + kids[b].triangles > kPacketLanes)
            continue;
          Aabb merged = kids[a].box;
          merged.extend(kids[b].box);
          const double saving = kids[a].box.half_area() + kids[b].box.half_area() - merged.half_area();
          if (saving >= 0.0 && saving > best_saving) {
            best_saving = saving;
            best_a = static_cast<int>(a);
            best_b = static_cast<int>(b);
          }
        }
      }
      if (best_a < 0) return;
      Candidate& into = kids[best_a];
      const Candidate& from = kids[best_b];
      into.box.extend(from.box);
      for (uint32_t p = 0; p < from.part_count; ++p) into.parts[into.part_count++] = from.parts[p];
      into.triangles += from.triangles;
      kids[best_b] = kids[--count];
    }
  }

  // First slot of a run of `triangles` slots, padding to a packet boundary
  // when that saves a packet test and the padding budget allows.
  uint64_t allocate_slots(uint32_t triangles) {
    const uint64_t lane = slot_ % kPacketLanes;
    const uint64_t packets_here = (lane + triangles + kPacketLanes - 1) / kPacketLanes;
    const uint64_t packets_aligned = (triangles + kPacketLanes - 1) / kPacketLanes;
    if (lane != 0 && packets_here > packets_aligned && padding_ + (kPacketLanes - lane) <= padding_budget_) {
      padding_ += kPacketLanes - lane;
      slot_ += kPacketLanes - lane;
    }
    const uint64_t first = slot_;
    slot_ += triangles;
    return first;
  }

  void write_slot(uint64_t slot, uint32_t position) {
    TrianglePacket& packet = out_->packets[slot / kPacketLanes];
    const uint32_t lane = static_cast<uint32_t>(slot % kPacketLanes);
    const uint32_t k = order_[position];
    const Triangle& tri = triangles_[k];
    const Vec3f* v[3] = {&tri.v0, &tri.v1, &tri.v2};
    for (int vertex = 0; vertex < 3; ++vertex) {
      for (int axis = 0; axis < 3; ++axis) packet.coord[3 * vertex + axis][lane] = (*v[vertex])[axis];
    }
    packet.geometry_id[lane] = ids_[k].geometry_id;
    packet.primitive_id[lane] = ids_[k].primitive_id;
  }

  // Writes the triangles under binary node b to consecutive slots from `slot`.
  uint64_t write_subtree(uint32_t b, uint64_t slot) {
    std::array<uint32_t, kMaxBvhDepth + 2> stack;
    uint32_t top = 0;
    stack[top++] = b;
    while (top > 0) {
      const BvhNode& node = nodes_[stack[--top]];
      if (node.is_leaf()) {
        for (uint32_t j = node.index; j < node.index + node.count; ++j) write_slot(slot++, j);
      } else {
        stack[top++] = node.index + 1;
        stack[top++] = node.index;
      }
    }
    return slot;
  }

  void make_node(uint32_t binary, uint32_t wide) {
    std::array<Candidate, kWideBvhWidth> kids;
    const uint32_t count = choose_children(binary, kids);
    std::array<uint32_t, kWideBvhWidth> inner_index{};
    WideBvhNode node = WideBvhNode::empty();
    for (uint32_t k = 0; k < count; ++k) {
      const Candidate& kid = kids[k];
      node.set_box(k, kid.box);
      if (kid.leaf) {
        assert(kid.triangles >= 1 && kid.triangles <= 255);
        const uint64_t first = allocate_slots(kid.triangles);
        node.child[k] = static_cast<uint32_t>(first);
        node.leaf_triangles[k] = static_cast<uint8_t>(kid.triangles);
        node.leaf_mask |= static_cast<uint8_t>(1u << k);
        if (out_ != nullptr) {
          uint64_t slot = first;
          for (uint32_t p = 0; p < kid.part_count; ++p) slot = write_subtree(kid.parts[p], slot);
        }
      } else {
        inner_index[k] = node_count_++;
        node.child[k] = inner_index[k];
        node.inner_mask |= static_cast<uint8_t>(1u << k);
      }
    }
    if (out_ != nullptr) out_->nodes[wide] = node;
    for (uint32_t k = 0; k < count; ++k) {
      if (!kids[k].leaf) make_node(kids[k].parts[0], inner_index[k]);
    }
  }

  std::span<const BvhNode> nodes_;
  std::span<const uint32_t> order_;
  std::span<const Triangle> triangles_;
  std::span<const TriangleId> ids_;
  std::vector<uint32_t> subtree_;  // triangles under each binary node
  uint64_t padding_budget_ = 0;

  WideBvh* out_ = nullptr;
  uint32_t node_count_ = 0;
  uint64_t slot_ = 0;
  uint64_t padding_ = 0;
};

TrianglePacket empty_packet() {
  TrianglePacket packet{};
  std::fill(std::begin(packet.geometry_id), std::end(packet.geometry_id), kInvalidId);
  std::fill(std::begin(packet.primitive_id), std::end(packet.primitive_id), kInvalidId);
  return packet;
}

}  // namespace

WideBvhCollapser::Result WideBvhCollapser::collapse(std::span<const BvhNode> nodes,
                                                    std::span<const uint32_t> order,
                                                    std::span<const Triangle> triangles,
                                                    std::span<const TriangleId> ids) {
  Collapse collapse(nodes, order, triangles, ids);
  const auto [node_count, packet_count] = collapse.count();
  Result result;
  result.tree.nodes.resize(node_count);
  result.tree.packets.assign(packet_count, empty_packet());
  collapse.fill(result.tree);
  result.peak_bytes = result.tree.memory_bytes() + collapse.scratch_bytes();
  return result;
}

// Wide nodes: every one but the root stands for a binary subtree of more than
// 8 triangles; those with fewer than 8 children have only leaves below them,
// so they are disjoint (<= n / 9), and the rest have 8 children, so there
// are at most (n / 9 + n) / 7 of them: 0.28 n in all, 256 B each. Packets:
// slots <= 1.25 n + 8. Scratch: 4 B per binary node (<= 2n).
uint64_t WideBvhCollapser::peak_bytes_bound(uint64_t n) {
  const uint64_t nodes = n * 2 / 7 + 2;
  const uint64_t packets = (n + n / 4 + 8) / kPacketLanes + 2;
  return nodes * sizeof(WideBvhNode) + packets * sizeof(TrianglePacket) + 8 * n + 4096;
}

}  // namespace outcore
