#include "core/accel/kdtree/kd_tree_builder.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace outcore {
namespace {

// A candidate plane a triangle's (clipped) bounds put on one axis. At one
// position, ends sort before planar before starts, which the sweep relies on.
enum EventType : uint8_t { kEnd = 0, kPlanar = 1, kStart = 2 };

struct Event {
  float position;
  uint32_t triangle;
  uint8_t axis;
  uint8_t type;
};

// A function object, so that sort and merge inline it.
struct EventLess {
  bool operator()(const Event& a, const Event& b) const {
    if (a.axis != b.axis) return a.axis < b.axis;
    if (a.position != b.position) return a.position < b.position;
    return a.type < b.type;
  }
};
constexpr EventLess event_less;

using Events = std::vector<Event>;

void add_events(uint32_t triangle, const Aabb& box, Events& out) {
  for (uint8_t axis = 0; axis < 3; ++axis) {
    if (box.lo[axis] == box.hi[axis]) {
      out.push_back({box.lo[axis], triangle, axis, kPlanar});
    } else {
      out.push_back({box.lo[axis], triangle, axis, kStart});
      out.push_back({box.hi[axis], triangle, axis, kEnd});
    }
  }
}

Aabb intersection(const Aabb& a, const Aabb& b) {
  Aabb out;
  out.lo = max(a.lo, b.lo);
  out.hi = min(a.hi, b.hi);
  return out;
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
  Aabb out;
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (std::size_t k = 0; k < count; ++k) {
    for (int axis = 0; axis < 3; ++axis) {
      const auto value = static_cast<float>(polygon[k][axis]);
      out.lo[axis] = std::min(out.lo[axis], std::nextafter(value, -kInf));
      out.hi[axis] = std::max(out.hi[axis], std::nextafter(value, kInf));
    }
  }
  return intersection(out, coarse);
}

enum Side : uint8_t { kBoth = 0, kBelowOnly = 1, kAboveOnly = 2 };

struct Split {
  int axis = -1;
  float position = 0;
  bool planar_below = true;  // triangles lying in the plane go below
  double cost = std::numeric_limits<double>::infinity();
};

class Build {
 public:
  Build(const std::vector<Triangle>& triangles, const KdTreeBuilder::Config& config, KdTree& tree)
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
    Events events;
    events.reserve(6 * triangles_.size());
    for (uint32_t k = 0; k < triangles_.size(); ++k) add_events(k, triangles_[k].bounds(), events);
    std::sort(events.begin(), events.end(), event_less);
    track(static_cast<int64_t>(events.capacity()));
    node(std::move(events), static_cast<uint32_t>(triangles_.size()), bounds, 1);
    return peak_events_ * sizeof(Event) + side_.size();
  }

 private:
  void track(int64_t delta) {
    live_events_ += delta;
    peak_events_ = std::max<int64_t>(peak_events_, live_events_);
  }
  void release(Events& events) {
    track(-static_cast<int64_t>(events.capacity()));
    Events().swap(events);
  }

  // The SAH cost of splitting `box` (extent e, half area box_area) at
  // `position` on `axis`: a child's half area is the face across the axis
  // plus its length along the axis times the other two extents.
  double cost(int axis, float position, const Aabb& box, const Vec3d& e, double box_area, uint32_t below,
              uint32_t above) const {
    const int a = (axis + 1) % 3, b = (axis + 2) % 3;
    const double face = e[a] * e[b], rim = e[a] + e[b];
    const double lower_area = face + (double{position} - box.lo[axis]) * rim;
    const double upper_area = face + (double{box.hi[axis]} - position) * rim;
    double c = config_.traversal_cost +
               config_.intersection_cost * (lower_area * below + upper_area * above) / box_area;
    if (below == 0 || above == 0) c *= 1.0 - config_.empty_bonus;
    return c;
  }

  // The sweep over a node's sorted events: the cheapest plane strictly inside
  // the box (a plane on the box's face would make a child of the same box).
  Split best_split(const Events& events, uint32_t n, const Aabb& box) const {
    Split best;
    const double box_area = box.half_area();
    if (!(box_area > 0.0)) return best;
    const Vec3d e(box.extent());
    std::array<uint32_t, 3> below{0, 0, 0}, above{n, n, n};
    std::size_t i = 0;
    while (i < events.size()) {
      const int axis = events[i].axis;
      const float position = events[i].position;
      uint32_t ending = 0, planar = 0, starting = 0;
      const auto at = [&](uint8_t type) {
        return i < events.size() && events[i].axis == axis && events[i].position == position &&
               events[i].type == type;
      };
      while (at(kEnd)) ++ending, ++i;
      while (at(kPlanar)) ++planar, ++i;
      while (at(kStart)) ++starting, ++i;
      above[axis] -= planar + ending;
      if (box.lo[axis] < position && position < box.hi[axis]) {
        const double planar_below = cost(axis, position, box, e, box_area, below[axis] + planar, above[axis]);
        const double planar_above = cost(axis, position, box, e, box_area, below[axis], above[axis] + planar);
        if (planar_below < best.cost) best = {axis, position, true, planar_below};
        if (planar_above < best.cost) best = {axis, position, false, planar_above};
      }
      below[axis] += starting + planar;
    }
    return best;
  }

  // Writes a leaf of the node's triangles (each has one start or planar
  // event on axis 0, which sort first).
  void leaf(const Events& events, uint32_t index) {
    const auto first = static_cast<uint32_t>(tree_.refs.size());
    for (const Event& e : events) {
      if (e.axis != 0) break;
      if (e.type != kEnd) tree_.refs.push_back(e.triangle);
    }
    tree_.nodes[index] = KdNode::leaf(first, static_cast<uint32_t>(tree_.refs.size()) - first);
  }

  void node(Events events, uint32_t n, const Aabb& box, uint32_t depth) {
    const auto index = static_cast<uint32_t>(tree_.nodes.size());
    tree_.nodes.emplace_back();
    Split split;
    if (n > 0 && depth < depth_limit_ && tree_.nodes.size() + 2 <= node_budget_) {
      split = best_split(events, n, box);
      if (!(split.cost < config_.intersection_cost * n)) split.axis = -1;
    }
    if (split.axis < 0) {
      leaf(events, index);
      release(events);
      return;
    }
    // Classify: every triangle of the node straddles until its events on the
    // split axis say otherwise.
    for (const Event& e : events) {
      if (e.axis == 0 && e.type != kEnd) side_[e.triangle] = kBoth;
    }
    for (const Event& e : events) {
      if (e.axis != split.axis) continue;
      if (e.type == kEnd && e.position <= split.position) {
        side_[e.triangle] = kBelowOnly;
      } else if (e.type == kStart && e.position >= split.position) {
        side_[e.triangle] = kAboveOnly;
      } else if (e.type == kPlanar) {
        const bool below =
            e.position < split.position || (e.position == split.position && split.planar_below);
        side_[e.triangle] = below ? kBelowOnly : kAboveOnly;
      }
    }
    Aabb lower = box, upper = box;
    lower.hi[split.axis] = split.position;
    upper.lo[split.axis] = split.position;
    Events below_only, above_only, below_new, above_new;
    uint32_t n_below = 0, n_above = 0;
    for (const Event& e : events) {
      const Side side = static_cast<Side>(side_[e.triangle]);
      if (side == kBelowOnly) {
        below_only.push_back(e);
      } else if (side == kAboveOnly) {
        above_only.push_back(e);
      } else if (e.axis == 0 && e.type != kEnd) {
        // A straddler, once (its first event): clipped to each child.
        const Aabb in_lower = clipped_bounds(triangles_[e.triangle], lower);
        const Aabb in_upper = clipped_bounds(triangles_[e.triangle], upper);
        if (!in_lower.empty()) add_events(e.triangle, in_lower, below_new), ++n_below;
        if (!in_upper.empty()) add_events(e.triangle, in_upper, above_new), ++n_above;
      }
      if (e.axis == 0 && e.type != kEnd) {
        n_below += side == kBelowOnly;
        n_above += side == kAboveOnly;
      }
    }
    // Over budget: this node stays a leaf (the tree's size is bounded).
    if (references_ + n_below + n_above - n > reference_budget_) {
      leaf(events, index);
      release(events);
      return;
    }
    references_ += n_below + n_above - n;
    track(static_cast<int64_t>(below_only.capacity() + above_only.capacity() + below_new.capacity() +
                               above_new.capacity()));
    release(events);
    Events below = merged(std::move(below_only), std::move(below_new));
    Events above = merged(std::move(above_only), std::move(above_new));
    node(std::move(below), n_below, lower, depth + 1);
    const auto above_index = static_cast<uint32_t>(tree_.nodes.size());
    node(std::move(above), n_above, upper, depth + 1);
    tree_.nodes[index] = KdNode::inner(split.axis, split.position, above_index);
  }

  // `kept` (sorted) and `added` (unsorted, few) as one sorted list.
  Events merged(Events kept, Events added) {
    std::sort(added.begin(), added.end(), event_less);
    Events out(kept.size() + added.size());
    track(static_cast<int64_t>(out.capacity()));
    std::merge(kept.begin(), kept.end(), added.begin(), added.end(), out.begin(), event_less);
    release(kept);
    release(added);
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

Status KdTreeBuilder::Config::validate() const {
  if (!(traversal_cost > 0.0f) || !std::isfinite(traversal_cost)) {
    return invalid_argument("kdtree: traversal_cost must be a positive number, got " +
                            std::to_string(traversal_cost));
  }
  if (!(intersection_cost > 0.0f) || !std::isfinite(intersection_cost)) {
    return invalid_argument("kdtree: intersection_cost must be a positive number, got " +
                            std::to_string(intersection_cost));
  }
  if (!(empty_bonus >= 0.0f && empty_bonus < 1.0f)) {
    return invalid_argument("kdtree: empty_bonus must be in [0, 1), got " + std::to_string(empty_bonus));
  }
  if (max_depth > kMaxKdDepth) {
    return invalid_argument("kdtree: max_depth must be at most " + std::to_string(kMaxKdDepth) + ", got " +
                            std::to_string(max_depth));
  }
  return Status::Ok();
}

uint32_t KdTreeBuilder::depth_limit(const Config& config, uint64_t n) {
  if (config.max_depth != 0) return config.max_depth;
  const double automatic = 8.0 + 1.3 * std::log2(static_cast<double>(std::max<uint64_t>(n, 1)));
  return std::min<uint32_t>(kMaxKdDepth, static_cast<uint32_t>(std::lround(automatic)));
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
  tree.records.reserve(triangles.size());
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    tree.records.push_back({triangles[k].unit_normal(), ids[k].geometry_id, ids[k].primitive_id});
  }
  tree.triangles = std::move(triangles);
  Build build(tree.triangles, config, tree);
  result.peak_bytes = build.run(tree.bounds);
  // Exact capacities: memory_bytes() then equals a reloaded tree's (the
  // subtree tier's accounting does not depend on where a brick came from).
  tree.nodes.shrink_to_fit();
  tree.refs.shrink_to_fit();
  tree.triangles.shrink_to_fit();
  return result;
}

}  // namespace outcore
