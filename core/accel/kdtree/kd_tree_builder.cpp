#include "core/accel/kdtree/kd_tree_builder.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace outcore {
namespace {

// A candidate plane a triangle's (clipped) bounds put on one axis, as one
// 64-bit key per axis list: the position's bits made to sort as the float
// does (high 32 bits), the type (bits 24-25), the triangle (low 24 bits;
// bricks have at most 2^24). Sorting keys sorts by position, then type: at
// one position ends before planar before starts, which the sweep relies on.
enum EventType : uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };

using Event = uint64_t;
using Events = std::vector<Event>;
using AxisEvents = std::array<Events, 3>;

constexpr uint32_t kTriangleBits = 24;
static_assert(KdTreeBuilder::kMaxTriangles <= (uint64_t{1} << kTriangleBits));

inline Event make_event(float position, EventType type, uint32_t triangle) {
  // +0 for -0, so that equal positions have equal keys.
  const uint32_t bits = std::bit_cast<uint32_t>(position + 0.0f);
  const uint32_t sortable = (bits & 0x80000000u) != 0 ? ~bits : bits | 0x80000000u;
  return (uint64_t{sortable} << 32) | (uint64_t{type} << kTriangleBits) | triangle;
}
inline float event_position(Event e) {
  const auto sortable = static_cast<uint32_t>(e >> 32);
  return std::bit_cast<float>((sortable & 0x80000000u) != 0 ? sortable & 0x7fffffffu : ~sortable);
}
inline uint32_t event_type(Event e) {
  return static_cast<uint32_t>(e >> kTriangleBits) & 3u;
}
inline uint32_t event_triangle(Event e) {
  return static_cast<uint32_t>(e) & ((1u << kTriangleBits) - 1);
}
// Position and type: what the sweep groups by.
inline uint64_t event_group(Event e) {
  return e >> kTriangleBits;
}

void add_events(uint32_t triangle, const Aabb& box, AxisEvents& out) {
  for (int axis = 0; axis < 3; ++axis) {
    if (box.lo[axis] == box.hi[axis]) {
      out[axis].push_back(make_event(box.lo[axis], kPlanar, triangle));
    } else {
      out[axis].push_back(make_event(box.lo[axis], kStart, triangle));
      out[axis].push_back(make_event(box.hi[axis], kEnd, triangle));
    }
  }
}

Aabb intersection(const Aabb& a, const Aabb& b) {
  Aabb out;
  out.lo = max(a.lo, b.lo);
  out.hi = min(a.hi, b.hi);
  return out;
}

// The float nearest v, one ulp further down (up): a bound that also covers
// the float64 clipping's own rounding (v finite and within float range, as
// clipped vertices of finite triangles are). Inline bit steps, not
// std::nextafter: this runs for every straddling triangle of every node.
float float_at_or_below(double v) {
  const auto f = static_cast<float>(v);
  if (f == 0.0f) return -std::numeric_limits<float>::denorm_min();
  const auto bits = std::bit_cast<uint32_t>(f);
  return std::bit_cast<float>(f > 0.0f ? bits - 1 : bits + 1);
}
float float_at_or_above(double v) {
  const auto f = static_cast<float>(v);
  if (f == 0.0f) return std::numeric_limits<float>::denorm_min();
  const auto bits = std::bit_cast<uint32_t>(f);
  return std::bit_cast<float>(f > 0.0f ? bits + 1 : bits - 1);
}

// The bounds of the part of `tri` inside `box` (Sutherland-Hodgman in
// float64 against the six planes), rounded outward to float and kept within
// the box; where float64 clipping leaves nothing of a triangle whose bounds
// still meet the box (a graze), those bounds within the box, so that no cell
// the triangle touches loses it. Empty when the triangle's bounds miss the box.
Aabb clipped_bounds(const Triangle& tri, const Aabb& box) {
  const Aabb coarse = intersection(tri.bounds(), box);
  if (coarse.empty()) return coarse;
  std::array<Vec3d, 9> polygon{Vec3d(tri.v0), Vec3d(tri.v1), Vec3d(tri.v2)};
  std::array<Vec3d, 9> next{};
  std::size_t count = 3;
  for (int axis = 0; axis < 3 && count > 0; ++axis) {
    for (int side = 0; side < 2 && count > 0; ++side) {
      const double plane = side == 0 ? box.lo[axis] : box.hi[axis];
      const auto inside = [&](const Vec3d& p) { return side == 0 ? p[axis] >= plane : p[axis] <= plane; };
      std::size_t kept = 0;
      for (std::size_t k = 0; k < count; ++k) {
        const Vec3d& a = polygon[k];
        const Vec3d& b = polygon[(k + 1) % count];
        if (inside(a)) next[kept++] = a;
        if (inside(a) != inside(b) && kept < next.size()) {
          const double s = (plane - a[axis]) / (b[axis] - a[axis]);
          Vec3d p = a + (b - a) * s;
          p[axis] = plane;
          next[kept++] = p;
        }
      }
      count = kept;
      polygon = next;
    }
  }
  if (count == 0) return coarse;
  Vec3d lo = polygon[0], hi = polygon[0];
  for (std::size_t k = 1; k < count; ++k) {
    lo = min(lo, polygon[k]);
    hi = max(hi, polygon[k]);
  }
  Aabb out;
  for (int axis = 0; axis < 3; ++axis) {
    out.lo[axis] = float_at_or_below(lo[axis]);
    out.hi[axis] = float_at_or_above(hi[axis]);
  }
  return intersection(out, coarse);
}

enum Side : uint8_t { kBoth = 0, kBelowOnly = 1, kAboveOnly = 2 };

struct KdSplit {
  int axis = -1;
  float position = 0;
  bool planar_below = true;  // triangles lying in the plane go below
  double cost = std::numeric_limits<double>::infinity();
};

class KdBuild {
 public:
  KdBuild(const std::vector<Triangle>& triangles, const KdTreeBuilder::Config& config, KdTree& tree)
      : triangles_(triangles),
        config_(config),
        tree_(tree),
        side_(triangles.size(), kBoth),
        depth_limit_(KdTreeBuilder::depth_limit(config, triangles.size())),
        reference_budget_(KdTreeBuilder::kMaxReferencesPerTriangle * triangles.size() + 64),
        node_budget_(4 * reference_budget_ + 1),
        references_(triangles.size()) {}

  // Returns the peak bytes of events held at once.
  uint64_t run(const Aabb& bounds) {
    AxisEvents events;
    for (Events& list : events) list.reserve(2 * triangles_.size());
    for (uint32_t k = 0; k < triangles_.size(); ++k) add_events(k, triangles_[k].bounds(), events);
    for (Events& list : events) std::sort(list.begin(), list.end());
    track(capacity(events));
    node(std::move(events), static_cast<uint32_t>(triangles_.size()), bounds, 1);
    return peak_events_ * sizeof(Event) + side_.size();
  }

 private:
  static int64_t capacity(const AxisEvents& events) {
    return static_cast<int64_t>(events[0].capacity() + events[1].capacity() + events[2].capacity());
  }
  void track(int64_t delta) {
    live_events_ += delta;
    peak_events_ = std::max<int64_t>(peak_events_, live_events_);
  }
  void release(Events& events) {
    track(-static_cast<int64_t>(events.capacity()));
    Events().swap(events);
  }
  void release(AxisEvents& events) {
    for (Events& list : events) release(list);
  }

  // The SAH cost of splitting `box` (extent e, scale = intersection cost over
  // its half area) at
  // `position` on `axis`: a child's half area is the face across the axis
  // plus its length along the axis times the other two extents.
  double cost(int axis, float position, const Aabb& box, const Vec3d& e, double scale, uint32_t below,
              uint32_t above) const {
    const int a = (axis + 1) % 3, b = (axis + 2) % 3;
    const double face = e[a] * e[b], rim = e[a] + e[b];
    const double lower_area = face + (double{position} - box.lo[axis]) * rim;
    const double upper_area = face + (double{box.hi[axis]} - position) * rim;
    double c = config_.traversal_cost + scale * (lower_area * below + upper_area * above);
    if (below == 0 || above == 0) c *= 1.0 - config_.empty_bonus;
    return c;
  }

  // The sweep over a node's sorted events, axis by axis: the cheapest plane
  // strictly inside the box (a plane on the box's face would make a child of
  // the same box).
  KdSplit best_split(const AxisEvents& events, uint32_t n, const Aabb& box) const {
    KdSplit best;
    const double box_area = box.half_area();
    if (!(box_area > 0.0)) return best;
    const double scale = config_.intersection_cost / box_area;
    const Vec3d e(box.extent());
    for (int axis = 0; axis < 3; ++axis) {
      const Events& list = events[axis];
      const std::size_t size = list.size();
      uint32_t below = 0, above = n;
      std::size_t i = 0;
      while (i < size) {
        const uint64_t position_key = list[i] >> 32;
        uint32_t counts[3] = {0, 0, 0};  // by type: ending, planar, starting
        do {
          ++counts[event_type(list[i])];
        } while (++i < size && (list[i] >> 32) == position_key);
        const uint32_t ending = counts[kEnd], planar = counts[kPlanar], starting = counts[kStart];
        const float position = event_position(list[i - 1]);
        above -= planar + ending;
        if (box.lo[axis] < position && position < box.hi[axis]) {
          const double planar_below = cost(axis, position, box, e, scale, below + planar, above);
          const double planar_above = cost(axis, position, box, e, scale, below, above + planar);
          if (planar_below < best.cost) best = {axis, position, true, planar_below};
          if (planar_above < best.cost) best = {axis, position, false, planar_above};
        }
        below += starting + planar;
      }
    }
    return best;
  }

  // Writes a leaf of the node's triangles (each has one start or planar
  // event on every axis).
  void leaf(const AxisEvents& events, uint32_t index) {
    const auto first = static_cast<uint32_t>(tree_.refs.size());
    for (const Event e : events[0]) {
      if (event_type(e) != kEnd) tree_.refs.push_back(event_triangle(e));
    }
    tree_.nodes[index] = KdNode::leaf(first, static_cast<uint32_t>(tree_.refs.size()) - first);
  }

  // Marks each of the node's triangles below, above or straddling `split`.
  void classify(const AxisEvents& events, const KdSplit& split) {
    for (const Event e : events[0]) {
      if (event_type(e) != kEnd) side_[event_triangle(e)] = kBoth;
    }
    for (const Event e : events[split.axis]) {
      const float position = event_position(e);
      const uint32_t type = event_type(e);
      uint8_t& side = side_[event_triangle(e)];
      if (type == kEnd && position <= split.position) {
        side = kBelowOnly;
      } else if (type == kStart && position >= split.position) {
        side = kAboveOnly;
      } else if (type == kPlanar) {
        const bool below = position < split.position || (position == split.position && split.planar_below);
        side = below ? kBelowOnly : kAboveOnly;
      }
    }
  }

  void node(AxisEvents events, uint32_t n, const Aabb& box, uint32_t depth) {
    const auto index = static_cast<uint32_t>(tree_.nodes.size());
    tree_.nodes.emplace_back();
    KdSplit split;
    if (n > 0 && depth < depth_limit_ && tree_.nodes.size() + 2 <= node_budget_) {
      split = best_split(events, n, box);
      if (!(split.cost < config_.intersection_cost * n)) split.axis = -1;
    }
    if (split.axis < 0) {
      leaf(events, index);
      release(events);
      return;
    }
    classify(events, split);
    Aabb lower = box, upper = box;
    lower.hi[split.axis] = split.position;
    upper.lo[split.axis] = split.position;
    AxisEvents below_only, above_only, below_new, above_new;
    uint32_t n_below = 0, n_above = 0;
    // Straddlers, once each (their start or planar event on axis 0): clipped
    // to each child.
    for (const Event e : events[0]) {
      if (event_type(e) == kEnd) continue;
      const uint32_t tri = event_triangle(e);
      const Side side = static_cast<Side>(side_[tri]);
      n_below += side == kBelowOnly;
      n_above += side == kAboveOnly;
      if (side != kBoth) continue;
      const Aabb in_lower = clipped_bounds(triangles_[tri], lower);
      const Aabb in_upper = clipped_bounds(triangles_[tri], upper);
      if (!in_lower.empty()) add_events(tri, in_lower, below_new), ++n_below;
      if (!in_upper.empty()) add_events(tri, in_upper, above_new), ++n_above;
    }
    // Over budget: this node stays a leaf (the tree's size is bounded).
    if (references_ + n_below + n_above - n > reference_budget_) {
      leaf(events, index);
      release(events);
      track(capacity(below_new) + capacity(above_new));
      release(below_new);
      release(above_new);
      return;
    }
    references_ += n_below + n_above - n;
    for (int axis = 0; axis < 3; ++axis) {
      // Exact sizes first: growing the lists is most of a small node's cost.
      std::size_t to_below = 0, to_above = 0;
      for (const Event e : events[axis]) {
        const uint8_t side = side_[event_triangle(e)];
        to_below += side == kBelowOnly;
        to_above += side == kAboveOnly;
      }
      below_only[axis].reserve(to_below);
      above_only[axis].reserve(to_above);
      for (const Event e : events[axis]) {
        const Side side = static_cast<Side>(side_[event_triangle(e)]);
        if (side == kBelowOnly) {
          below_only[axis].push_back(e);
        } else if (side == kAboveOnly) {
          above_only[axis].push_back(e);
        }
      }
    }
    track(capacity(below_only) + capacity(above_only) + capacity(below_new) + capacity(above_new));
    release(events);
    AxisEvents below = merged(std::move(below_only), std::move(below_new));
    AxisEvents above = merged(std::move(above_only), std::move(above_new));
    node(std::move(below), n_below, lower, depth + 1);
    const auto above_index = static_cast<uint32_t>(tree_.nodes.size());
    node(std::move(above), n_above, upper, depth + 1);
    tree_.nodes[index] = KdNode::inner(split.axis, split.position, above_index);
  }

  // Per axis, `kept` (sorted) and `added` (unsorted, few) as one sorted list.
  AxisEvents merged(AxisEvents kept, AxisEvents added) {
    AxisEvents out;
    for (int axis = 0; axis < 3; ++axis) {
      Events& add = added[axis];
      if (add.empty()) {
        out[axis] = std::move(kept[axis]);
        continue;
      }
      std::sort(add.begin(), add.end());
      out[axis].resize(kept[axis].size() + add.size());
      track(static_cast<int64_t>(out[axis].capacity()));
      std::merge(kept[axis].begin(), kept[axis].end(), add.begin(), add.end(), out[axis].begin());
      release(kept[axis]);
      release(add);
    }
    return out;
  }

  const std::vector<Triangle>& triangles_;
  const KdTreeBuilder::Config& config_;
  KdTree& tree_;
  std::vector<uint8_t> side_;
  uint32_t depth_limit_;
  uint64_t reference_budget_, node_budget_;
  uint64_t references_;
  int64_t live_events_ = 0, peak_events_ = 0;
};

}  // namespace

uint32_t KdTreeBuilder::depth_limit(const Config& config, uint64_t n) {
  return config.depth_limit(n, kMaxKdDepth);
}

uint64_t KdTreeBuilder::tree_bytes_bound(uint64_t n) {
  const uint64_t references = kMaxReferencesPerTriangle * n + 64;
  const uint64_t nodes = 4 * references + 1;
  return nodes * sizeof(KdNode) + references * sizeof(uint32_t) +
         n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// Events: at most six per reference; those held at once are the pending
// subtrees' (disjoint, so within the reference budget) plus, while a node
// splits, its own list and its children's: at most three times the budget.
uint64_t KdTreeBuilder::peak_bytes_bound(uint64_t n) {
  const uint64_t references = kMaxReferencesPerTriangle * n + 64;
  return 3 * 6 * references * sizeof(Event) + n;
}

KdTreeBuilder::Result KdTreeBuilder::build(std::vector<Triangle> triangles,
                                           const std::vector<TriangleId>& ids, const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  KdTree& tree = result.tree;
  if (triangles.empty()) return result;
  for (const Triangle& tri : triangles) tree.bounds.extend(tri.bounds());
  tree.adopt_triangles(std::move(triangles), ids);
  KdBuild build(tree.triangles, config, tree);
  result.peak_bytes = build.run(tree.bounds);
  tree.trim();
  return result;
}

}  // namespace outcore
