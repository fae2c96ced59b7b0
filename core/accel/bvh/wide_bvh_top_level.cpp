#include "core/accel/bvh/wide_bvh_top_level.h"

#include <algorithm>
#include <cstdint>

namespace outcore {
namespace {

struct Range {
  uint32_t first, count;
};

class TopLevelBuild {
 public:
  explicit TopLevelBuild(std::span<const Aabb> boxes) : boxes_(boxes) {
    for (uint32_t i = 0; i < boxes.size(); ++i)
      if (!boxes[i].empty()) order_.push_back(i);
  }

  std::vector<WideBvhNode> run() {
    if (!order_.empty()) make_node({0, static_cast<uint32_t>(order_.size())});
    return std::move(nodes_);
  }

 private:
  // Splits `range` at the median of its box centres along their widest axis.
  std::pair<Range, Range> split(Range range) {
    Aabb centres;
    for (uint32_t i = range.first; i < range.first + range.count; ++i)
      centres.extend(boxes_[order_[i]].center());
    const int axis = centres.largest_axis();
    const auto begin = order_.begin() + range.first;
    const uint32_t half = range.count / 2;
    std::nth_element(begin, begin + half, begin + range.count, [&](uint32_t a, uint32_t b) {
      const float ca = boxes_[a].center()[axis], cb = boxes_[b].center()[axis];
      return ca < cb || (ca == cb && a < b);
    });
    return {{range.first, half}, {range.first + half, range.count - half}};
  }

  uint32_t make_node(Range range) {
    const auto index = static_cast<uint32_t>(nodes_.size());
    nodes_.emplace_back();
    // Up to 8 groups: split the largest group until each is one tree or
    // there are 8.
    std::vector<Range> groups{range};
    while (groups.size() < kWideBvhWidth) {
      auto largest = std::max_element(groups.begin(), groups.end(),
                                      [](const Range& a, const Range& b) { return a.count < b.count; });
      if (largest->count < 2) break;
      const auto [left, right] = split(*largest);
      *largest = left;
      groups.push_back(right);
    }
    WideBvhNode node = WideBvhNode::empty();
    for (uint32_t k = 0; k < groups.size(); ++k) {
      const Range g = groups[k];
      Aabb box;
      for (uint32_t i = g.first; i < g.first + g.count; ++i) box.extend(boxes_[order_[i]]);
      node.set_box(k, box);
      if (g.count == 1) {
        node.child[k] = order_[g.first];
        node.leaf_triangles[k] = 1;
        node.leaf_mask |= static_cast<uint8_t>(1u << k);
      } else {
        node.child[k] = make_node(g);  // after this node: children follow their parent
        node.inner_mask |= static_cast<uint8_t>(1u << k);
      }
    }
    nodes_[index] = node;
    return index;
  }

  std::span<const Aabb> boxes_;
  std::vector<uint32_t> order_;
  std::vector<WideBvhNode> nodes_;
};

}  // namespace

std::vector<WideBvhNode> build_wide_top_level(std::span<const Aabb> boxes) {
  return TopLevelBuild(boxes).run();
}

}  // namespace outcore
