#include "core/dynamic/bkd_tree.h"

#include <algorithm>
#include <cassert>

namespace outcore {
namespace {

struct Interval {
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  void extend(float l, float h) {
    lo = std::min(lo, l);
    hi = std::max(hi, h);
  }
};

// The box of everything under a child, for the cost (not stored).
Aabb subtree_box(const std::vector<BkdNode>& nodes, const BkdNode& node, int c, std::span<const Aabb> boxes) {
  if ((node.leaf_mask >> c) & 1u) return boxes[node.child[c]];
  const BkdNode& below = nodes[node.child[c]];
  Aabb box = subtree_box(nodes, below, 0, boxes);
  box.extend(subtree_box(nodes, below, 1, boxes));
  return box;
}

}  // namespace

uint32_t BkdTree::make(std::span<uint32_t> items, std::span<const Aabb> boxes) {
  const auto index = static_cast<uint32_t>(nodes_.size());
  nodes_.emplace_back();
  BkdNode node;
  if (items.size() <= 2) {
    node.child[0] = items[0];
    node.child[1] = items.back();
    node.leaf_mask = 3;
  } else {
    Aabb centres;
    for (const uint32_t i : items) centres.extend(boxes[i].center());
    node.axis = static_cast<uint8_t>(centres.largest_axis());
    const std::size_t half = items.size() / 2;
    std::nth_element(items.begin(), items.begin() + half, items.end(), [&](uint32_t a, uint32_t b) {
      const float ca = boxes[a].center()[node.axis], cb = boxes[b].center()[node.axis];
      return ca < cb || (ca == cb && a < b);
    });
    node.child[0] = make(items.first(half), boxes);
    node.child[1] = make(items.subspan(half), boxes);
  }
  nodes_[index] = node;
  return index;
}

BkdTree BkdTree::build(std::span<const Aabb> boxes) {
  BkdTree tree;
  std::vector<uint32_t> items;
  for (uint32_t i = 0; i < boxes.size(); ++i)
    if (!boxes[i].empty()) items.push_back(i);
  if (items.empty()) return tree;
  tree.nodes_.reserve(items.size());
  tree.make(items, boxes);
  tree.refit(boxes);
  return tree;
}

void BkdTree::refit(std::span<const Aabb> boxes) {
  // Children follow their parent: bottom-up is reverse order. Each node's
  // interval along its parent's axis comes from its own children's boxes,
  // so inner intervals are recomputed from full boxes kept per node here.
  std::vector<Aabb> below(nodes_.size());
  for (std::size_t i = nodes_.size(); i-- > 0;) {
    BkdNode& node = nodes_[i];
    Aabb all;
    for (int c = 0; c < 2; ++c) {
      const Aabb& box = ((node.leaf_mask >> c) & 1u) ? boxes[node.child[c]] : below[node.child[c]];
      node.lo[c] = box.lo[node.axis];
      node.hi[c] = box.hi[node.axis];
      all.extend(box);
    }
    below[i] = all;
  }
  bounds_ = nodes_.empty() ? Aabb{} : below[0];
}

double BkdTree::cost(std::span<const Aabb> boxes) const {
  if (nodes_.empty()) return 0;
  Aabb root = subtree_box(nodes_, nodes_[0], 0, boxes);
  root.extend(subtree_box(nodes_, nodes_[0], 1, boxes));
  const double area = root.half_area();
  if (!(area > 0)) return 0;
  // A child is entered when the ray meets the root box cut to the child's
  // slab: its probability is that cut box's area over the root's.
  double cost = 1;
  for (const BkdNode& node : nodes_) {
    for (int c = 0; c < 2; ++c) {
      Aabb cut = root;
      cut.lo[node.axis] = std::max(cut.lo[node.axis], node.lo[c]);
      cut.hi[node.axis] = std::min(cut.hi[node.axis], node.hi[c]);
      cost += cut.half_area() / area;
    }
  }
  return cost;
}

}  // namespace outcore
