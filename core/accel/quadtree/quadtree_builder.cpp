#include "core/accel/quadtree/quadtree_builder.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include "core/geometry/triangle_box_overlap.h"

namespace outcore {
namespace {

// A node waiting to be made: its slot, box, depth and triangles.
struct QuadPendingNode {
  uint32_t slot;
  Aabb box;
  uint32_t depth;
  std::vector<uint32_t> triangles;
};

class QuadtreeBuild {
 public:
  QuadtreeBuild(const std::vector<Triangle>& triangles, const QuadtreeBuilder::Config& config, Quadtree& tree)
      : triangles_(triangles), tree_(tree), axes_(quadtree_axes(tree.bounds)), config_(config) {
    bounds_.reserve(triangles.size());
    for (const Triangle& tri : triangles) bounds_.push_back(tri.bounds());
    const uint64_t n = triangles.size();
    references_cap_ = QuadtreeBuilder::references_cap(n);
    nodes_cap_ = QuadtreeBuilder::nodes_cap(n);
    depth_limit_ = QuadtreeBuilder::depth_limit(config, n);
  }

  // Returns the peak scratch bytes.
  uint64_t run() {
    QuadPendingNode root{0, tree_.bounds, 0, {}};
    root.triangles.resize(triangles_.size());
    for (uint32_t k = 0; k < root.triangles.size(); ++k) root.triangles[k] = k;
    tree_.nodes.push_back({});
    outstanding_ = root.triangles.size();
    std::vector<QuadPendingNode> stack;
    stack.push_back(std::move(root));
    while (!stack.empty()) {
      QuadPendingNode node = std::move(stack.back());
      stack.pop_back();
      make(node, stack);
      peak_ = std::max(peak_, outstanding_ * sizeof(uint32_t) + stack.capacity() * sizeof(QuadPendingNode));
    }
    return peak_ + bounds_.capacity() * sizeof(Aabb);
  }

 private:
  // The extent along w of the triangles' bounds.
  std::pair<float, float> w_extent(const std::vector<uint32_t>& triangles) const {
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (const uint32_t tri : triangles) {
      lo = std::min(lo, bounds_[tri].lo[axes_.w]);
      hi = std::max(hi, bounds_[tri].hi[axes_.w]);
    }
    return {lo, hi};
  }

  void make(QuadPendingNode& node, std::vector<QuadPendingNode>& stack) {
    const std::size_t count = node.triangles.size();
    const auto [w_lo, w_hi] = count == 0 ? std::pair<float, float>{0.0f, 0.0f} : w_extent(node.triangles);
    if (count > config_.max_leaf_size && node.depth < depth_limit_ && tree_.nodes.size() + 4 <= nodes_cap_) {
      std::array<std::vector<uint32_t>, 4> children = file(node);
      std::size_t filed = 0;
      for (const auto& child : children) filed += child.size();
      // Cut unless the triangles would be copied into most children (cells
      // far smaller than the triangles), or the budget would be passed.
      if (filed <= 2 * count && outstanding_ + filed - count <= references_cap_) {
        outstanding_ += filed - count;
        const uint32_t first_child = static_cast<uint32_t>(tree_.nodes.size());
        tree_.nodes[node.slot] = QuadtreeNode::inner(first_child, w_lo, w_hi);
        tree_.nodes.resize(tree_.nodes.size() + 4);
        const float middle_u = quadtree_middle(node.box, axes_.u);
        const float middle_v = quadtree_middle(node.box, axes_.v);
        for (uint32_t k = 4; k-- > 0;) {
          stack.push_back({first_child + k, quadtree_child_box(node.box, axes_, middle_u, middle_v, k),
                           node.depth + 1, std::move(children[k])});
        }
        return;
      }
    }
    tree_.nodes[node.slot] = QuadtreeNode::leaf(static_cast<uint32_t>(tree_.refs.size()),
                                                static_cast<uint32_t>(count), w_lo, w_hi);
    tree_.refs.insert(tree_.refs.end(), node.triangles.begin(), node.triangles.end());
  }

  // The triangles of each child: those whose bounds overlap its closed
  // column in the plane and, when they reach across both middles, that may
  // touch it (a connected triangle spread along one of the plane's axes
  // only touches every child its bounds reach).
  std::array<std::vector<uint32_t>, 4> file(const QuadPendingNode& node) const {
    std::array<std::vector<uint32_t>, 4> children;
    const float middle_u = quadtree_middle(node.box, axes_.u);
    const float middle_v = quadtree_middle(node.box, axes_.v);
    const double margin = cell_filing_margin(node.box, Vec3d(node.box.hi) - Vec3d(node.box.lo));
    for (const uint32_t tri : node.triangles) {
      const Aabb& b = bounds_[tri];
      const uint32_t low_mask = (b.lo[axes_.u] <= middle_u ? 1u : 0u) | (b.lo[axes_.v] <= middle_v ? 2u : 0u);
      const uint32_t high_mask =
          (b.hi[axes_.u] >= middle_u ? 1u : 0u) | (b.hi[axes_.v] >= middle_v ? 2u : 0u);
      const bool test_each_child = (low_mask & high_mask) == 3u;
      std::optional<TriangleBoxOverlap> overlap;
      if (test_each_child) overlap.emplace(triangles_[tri]);
      for (uint32_t k = 0; k < 4; ++k) {
        // Child k's half along each axis must be one the bounds reach.
        if ((~k & ~low_mask & 3u) != 0 || (k & ~high_mask & 3u) != 0) continue;
        if (test_each_child) {
          const Aabb box = quadtree_child_box(node.box, axes_, middle_u, middle_v, k);
          if (!overlap->may_touch_overlapping_column(Vec3d(box.lo), Vec3d(box.hi), margin, axes_.w)) continue;
        }
        children[k].push_back(tri);
      }
    }
    return children;
  }

  const std::vector<Triangle>& triangles_;
  Quadtree& tree_;
  const QuadtreeAxes axes_;
  const QuadtreeBuilder::Config& config_;
  std::vector<Aabb> bounds_;
  uint64_t references_cap_ = 0, nodes_cap_ = 0;
  uint32_t depth_limit_ = 0;
  uint64_t outstanding_ = 0;  // references in leaves made and nodes pending
  uint64_t peak_ = 0;
};

}  // namespace

uint64_t QuadtreeBuilder::tree_bytes_bound(uint64_t n) {
  return nodes_cap(n) * sizeof(QuadtreeNode) + references_cap(n) * sizeof(uint32_t) +
         n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// Triangle bounds, the pending lists and a node's four children's lists
// (within the reference budget twice), and the stack's entries.
uint64_t QuadtreeBuilder::peak_bytes_bound(uint64_t n) {
  return n * sizeof(Aabb) + 2 * references_cap(n) * sizeof(uint32_t) +
         (3 * kMaxQuadtreeDepth + 1) * sizeof(QuadPendingNode);
}

QuadtreeBuilder::Result QuadtreeBuilder::build(std::vector<Triangle> triangles,
                                               const std::vector<TriangleId>& ids, const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  Quadtree& tree = result.tree;
  if (triangles.empty()) return result;
  for (const Triangle& tri : triangles) tree.bounds.extend(tri.bounds());
  tree.adopt_triangles(std::move(triangles), ids);
  QuadtreeBuild build(tree.triangles, config, tree);
  result.peak_bytes = build.run();
  tree.trim();
  return result;
}

}  // namespace outcore
