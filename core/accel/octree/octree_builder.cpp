#include "core/accel/octree/octree_builder.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <optional>
#include <utility>

#include "core/geometry/triangle_box_overlap.h"

namespace outcore {
namespace {

// A node waiting to be made: its slot, box, depth and triangles.
struct OctPendingNode {
  uint32_t slot;
  Aabb box;
  uint32_t depth;
  std::vector<uint32_t> triangles;
};

class OctreeBuild {
 public:
  OctreeBuild(const std::vector<Triangle>& triangles, const OctreeBuilder::Config& config, Octree& tree)
      : triangles_(triangles), config_(config), tree_(tree) {
    bounds_.reserve(triangles.size());
    for (const Triangle& tri : triangles) bounds_.push_back(tri.bounds());
    const uint64_t n = triangles.size();
    references_cap_ = OctreeBuilder::references_cap(n);
    nodes_cap_ = OctreeBuilder::nodes_cap(n);
    depth_limit_ = OctreeBuilder::depth_limit(config, n);
  }

  // Returns the peak scratch bytes.
  uint64_t run() {
    OctPendingNode root{0, tree_.bounds, 0, {}};
    root.triangles.resize(triangles_.size());
    for (uint32_t k = 0; k < root.triangles.size(); ++k) root.triangles[k] = k;
    tree_.nodes.push_back(OctreeNode::leaf(0, 0));
    outstanding_ = root.triangles.size();
    std::vector<OctPendingNode> stack;
    stack.push_back(std::move(root));
    while (!stack.empty()) {
      OctPendingNode node = std::move(stack.back());
      stack.pop_back();
      make(node, stack);
      peak_ = std::max(peak_, outstanding_ * sizeof(uint32_t) + stack.capacity() * sizeof(OctPendingNode));
    }
    return peak_ + bounds_.capacity() * sizeof(Aabb);
  }

 private:
  void make(OctPendingNode& node, std::vector<OctPendingNode>& stack) {
    const std::size_t count = node.triangles.size();
    if (count > config_.max_leaf_size && node.depth < depth_limit_ && tree_.nodes.size() + 8 <= nodes_cap_) {
      std::array<std::vector<uint32_t>, 8> children = file(node);
      std::size_t filed = 0;
      for (const auto& child : children) filed += child.size();
      // Cut unless the triangles would be copied into most children (cells
      // far smaller than the triangles, or triangles through one point), or
      // the budget would be passed. All in one child is still a cut: the
      // child's box is smaller, and the next level separates them.
      if (filed <= 4 * count && outstanding_ + filed - count <= references_cap_) {
        outstanding_ += filed - count;
        const uint32_t first_child = static_cast<uint32_t>(tree_.nodes.size());
        tree_.nodes[node.slot] = OctreeNode::inner(first_child);
        tree_.nodes.resize(tree_.nodes.size() + 8, OctreeNode::leaf(0, 0));
        const Vec3f middle = octree_middle(node.box);
        for (uint32_t k = 8; k-- > 0;) {
          stack.push_back({first_child + k, octree_child_box(node.box, middle, k), node.depth + 1,
                           std::move(children[k])});
        }
        return;
      }
    }
    tree_.nodes[node.slot] =
        OctreeNode::leaf(static_cast<uint32_t>(tree_.refs.size()), static_cast<uint32_t>(count));
    tree_.refs.insert(tree_.refs.end(), node.triangles.begin(), node.triangles.end());
  }

  // The triangles of each child: those whose bounds overlap its closed box
  // and, when they reach across the middle along two or more axes, that may
  // touch it (a connected triangle spread along one axis only touches every
  // child its bounds reach).
  std::array<std::vector<uint32_t>, 8> file(const OctPendingNode& node) const {
    std::array<std::vector<uint32_t>, 8> children;
    const Vec3f middle = octree_middle(node.box);
    const double margin = cell_filing_margin(node.box, Vec3d(node.box.hi) - Vec3d(node.box.lo));
    for (const uint32_t tri : node.triangles) {
      const Aabb& b = bounds_[tri];
      uint32_t low_mask = 0, high_mask = 0;
      for (int a = 0; a < 3; ++a) {
        if (b.lo[a] <= middle[a]) low_mask |= 1u << a;
        if (b.hi[a] >= middle[a]) high_mask |= 1u << a;
      }
      const uint32_t spread = low_mask & high_mask;
      const bool test_each_child = (spread & (spread - 1)) != 0;  // two or more axes
      std::optional<TriangleBoxOverlap> overlap;
      if (test_each_child) overlap.emplace(triangles_[tri]);
      for (uint32_t k = 0; k < 8; ++k) {
        // Child k's half along axis a must be one the bounds reach.
        if ((~k & ~low_mask & 7u) != 0 || (k & ~high_mask & 7u) != 0) continue;
        if (test_each_child) {
          const Aabb box = octree_child_box(node.box, middle, k);
          if (!overlap->may_touch_overlapping_box(Vec3d(box.lo), Vec3d(box.hi), margin)) continue;
        }
        children[k].push_back(tri);
      }
    }
    return children;
  }

  const std::vector<Triangle>& triangles_;
  const OctreeBuilder::Config& config_;
  Octree& tree_;
  std::vector<Aabb> bounds_;
  uint64_t references_cap_ = 0, nodes_cap_ = 0;
  uint32_t depth_limit_ = 0;
  uint64_t outstanding_ = 0;  // references in leaves made and nodes pending
  uint64_t peak_ = 0;
};

}  // namespace

uint64_t OctreeBuilder::tree_bytes_bound(uint64_t n) {
  return nodes_cap(n) * sizeof(OctreeNode) + references_cap(n) * sizeof(uint32_t) +
         n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// Triangle bounds, the pending lists and a node's eight children's lists
// (within the reference budget twice), and the stack's entries.
uint64_t OctreeBuilder::peak_bytes_bound(uint64_t n) {
  return n * sizeof(Aabb) + 2 * references_cap(n) * sizeof(uint32_t) +
         (7 * kMaxOctreeDepth + 1) * sizeof(OctPendingNode);
}

OctreeBuilder::Result OctreeBuilder::build(std::vector<Triangle> triangles,
                                           const std::vector<TriangleId>& ids, const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  Octree& tree = result.tree;
  if (triangles.empty()) return result;
  for (const Triangle& tri : triangles) tree.bounds.extend(tri.bounds());
  tree.adopt_triangles(std::move(triangles), ids);
  OctreeBuild build(tree.triangles, config, tree);
  result.peak_bytes = build.run();
  tree.trim();
  return result;
}

}  // namespace outcore
