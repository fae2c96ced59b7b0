// QuadtreeBuilder: a quadtree over a brick's triangles in linear time per
// level (O(N depth)), as the octree's builder but cutting only the plane's
// two axes (quadtree.h): a node holding more than max_leaf_size triangles,
// above the depth limit, is cut into its four children and each triangle is
// filed under the children whose column it may touch (bounds overlap in the
// plane, and for a triangle whose bounds reach across both middles the
// column's separating axes, each edge crossed with w,
// TriangleBoxOverlap::may_touch_overlapping_column in
// core/geometry/triangle_box_overlap.h, on the column grown by a tiny
// margin: conservative, a triangle is never left out of a cell it touches). Each node records the extent
// along w of its triangles' bounds. A node stays a leaf when its children would hold more than twice its
// triangles (cells far smaller than the triangles), or when the tree would exceed its reference or node
// budget, which bounds memory for the cache's reservation.
//
// Thread-safety: build() is reentrant (no shared state).
#pragma once

#include <cstdint>
#include <vector>

#include "core/accel/octree/subdivision_config.h"
#include "core/accel/quadtree/quadtree.h"
#include "core/geometry/triangle.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

class QuadtreeBuilder {
 public:
  using Config = SubdivisionConfig<QuadtreeNode>;

  static constexpr uint64_t kMaxReferencesPerTriangle = 8;
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 24;

  struct Result {
    Quadtree tree;
    uint64_t peak_bytes = 0;  // the build's own scratch at its largest (bounds, pending lists)
  };

  // triangles: usable ones (finite, not degenerate); ids[k] belongs to
  // triangles[k]. The tree keeps them in this order.
  static Result build(std::vector<Triangle> triangles, const std::vector<TriangleId>& ids,
                      const Config& config);

  // Upper bounds, for n triangles: the tree's arrays, and the build's peak
  // scratch.
  static uint64_t tree_bytes_bound(uint64_t n);
  static uint64_t peak_bytes_bound(uint64_t n);
  // The budgets build() keeps (the serialiser checks payloads against them).
  static uint64_t references_cap(uint64_t n) { return kMaxReferencesPerTriangle * n + 64; }
  static uint64_t nodes_cap(uint64_t n) { return 4 * references_cap(n) + 1; }
  // The depth limit a build of n triangles uses.
  static uint32_t depth_limit(const Config& config, uint64_t n) { return config.depth_limit(n); }
};

}  // namespace outcore
