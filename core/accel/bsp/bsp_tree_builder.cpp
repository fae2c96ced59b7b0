#include "core/accel/bsp/bsp_tree_builder.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "core/accel/bsp/bsp_directions.h"
#include "core/accel/bsp/bsp_polytope.h"

namespace outcore {
namespace {

constexpr uint32_t kK = kBspDirectionCount;
constexpr float kInf = std::numeric_limits<float>::infinity();
// Extents are widened by this times |p|_1: float64's error in n . p and in
// the clipped points is within a few 2^-53 |p|_1.
constexpr double kExtentMargin = 0x1p-40;
// The polytopes on the recursion's path, at most (bytes, for the bounds).
constexpr uint64_t kPolytopeBytes = 64 * 1024;

using Extents = std::array<float, kK>;

// A k-DOP: the closed interval [lo[k], hi[k]] of n_k . p for every direction.
struct Dop {
  Extents lo, hi;
};

struct Ref {
  uint32_t triangle;
  Dop extents;  // of the triangle's part in the node's cell
};
using Refs = std::vector<Ref>;

float round_down(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) > x) f = std::nextafter(f, -kInf);
  return f;
}
float round_up(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, kInf);
  return f;
}

// The extents of a polygon's points along every direction, widened and
// rounded outward.
Dop polygon_extents(const Vec3d* points, std::size_t count) {
  std::array<double, kK> lo, hi;
  lo.fill(std::numeric_limits<double>::infinity());
  hi.fill(-std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < count; ++i) {
    const Vec3d& p = points[i];
    const double margin = kExtentMargin * (std::fabs(p.x) + std::fabs(p.y) + std::fabs(p.z));
    for (uint32_t k = 0; k < kK; ++k) {
      const double h = bsp_dot(k, p);
      lo[k] = std::min(lo[k], h - margin);
      hi[k] = std::max(hi[k], h + margin);
    }
  }
  Dop out;
  for (uint32_t k = 0; k < kK; ++k) {
    out.lo[k] = round_down(lo[k]);
    out.hi[k] = round_up(hi[k]);
  }
  return out;
}

Dop triangle_extents(const Triangle& tri) {
  const std::array<Vec3d, 3> v{Vec3d(tri.v0), Vec3d(tri.v1), Vec3d(tri.v2)};
  return polygon_extents(v.data(), v.size());
}

// `polygon` (count points) clipped in float64 to n_k . p <= s (keep_below) or
// >= s, in place.
void clip_polygon(std::array<Vec3d, 32>& polygon, std::size_t& count, uint32_t k, double s, bool keep_below) {
  std::array<Vec3d, 32> next;
  std::size_t kept = 0;
  const auto inside = [&](double h) { return keep_below ? h <= s : h >= s; };
  for (std::size_t i = 0; i < count; ++i) {
    const Vec3d& a = polygon[i];
    const Vec3d& b = polygon[(i + 1) % count];
    const double ha = bsp_dot(k, a), hb = bsp_dot(k, b);
    if (inside(ha) && kept < next.size()) next[kept++] = a;
    if (inside(ha) != inside(hb) && kept < next.size()) next[kept++] = a + (b - a) * ((s - ha) / (hb - ha));
  }
  count = kept;
  polygon = next;
}

// ref's extents narrowed to `cell`: the triangle clipped by every plane of
// the cell it crosses; where float64 leaves nothing of it (a graze), the
// previous extents (still conservative: the cell lies within the parent's).
// Then clamped to the cell, whose intervals are exact.
void narrow_to(Ref& ref, const Triangle& tri, const Dop& cell) {
  const Dop whole = triangle_extents(tri);
  std::array<Vec3d, 32> polygon{Vec3d(tri.v0), Vec3d(tri.v1), Vec3d(tri.v2)};
  std::size_t count = 3;
  for (uint32_t k = 0; k < kK && count > 0; ++k) {
    if (whole.lo[k] < cell.lo[k]) clip_polygon(polygon, count, k, cell.lo[k], false);
    if (count > 0 && whole.hi[k] > cell.hi[k]) clip_polygon(polygon, count, k, cell.hi[k], true);
  }
  if (count > 0) {
    const Dop clipped = polygon_extents(polygon.data(), count);
    for (uint32_t k = 0; k < kK; ++k) {
      ref.extents.lo[k] = std::max(ref.extents.lo[k], clipped.lo[k]);
      ref.extents.hi[k] = std::min(ref.extents.hi[k], clipped.hi[k]);
    }
  }
  for (uint32_t k = 0; k < kK; ++k) {
    float& lo = ref.extents.lo[k];
    float& hi = ref.extents.hi[k];
    lo = std::max(lo, cell.lo[k]);
    hi = std::min(hi, cell.hi[k]);
    // Only when the triangle misses the cell (beyond the margins): any
    // point of the cell will do.
    if (lo > hi) hi = lo = std::min(lo, cell.hi[k]);
  }
}

// A child's surface area as a function of the plane's position u in [0, 1]
// along the cell: the quadratic through its values at 0, 1/2 and 1.
double quadratic(double f0, double f_half, double f1, double u) {
  return f0 * (1.0 - u) * (1.0 - 2.0 * u) + 4.0 * f_half * u * (1.0 - u) + f1 * u * (2.0 * u - 1.0);
}

struct BspSplit {
  int direction = -1;
  float position = 0;
  double cost = std::numeric_limits<double>::infinity();
};

// The surface areas of both children of a cell, for planes along one
// direction.
struct AreaModel {
  double lo = 0, hi = 0;  // the cell's extent along the direction
  double below_lo = 0, below_half = 0, above_half = 0, above_hi = 0, whole = 0;

  AreaModel(const BspPolytope& cell, uint32_t k, double area) : whole(area) {
    cell.extent(k, lo, hi);
    double unused;
    cell.split_areas(k, lo, below_lo, unused);
    cell.split_areas(k, 0.5 * (lo + hi), below_half, above_half);
    // Just below the top: the part above is the face there, twice (at the
    // top itself every vertex counts as below).
    cell.split_areas(k, hi - 1e-9 * (hi - lo), unused, above_hi);
  }
  void at(double s, double& below, double& above) const {
    const double u = (s - lo) / (hi - lo);
    below = std::max(0.0, quadratic(below_lo, below_half, whole, u));
    above = std::max(0.0, quadratic(whole, above_half, above_hi, u));
    // The children's surfaces cover the cell's (and the section twice): an
    // approximation below that would make a split that keeps every triangle
    // on both sides look cheaper than a leaf.
    const double sum = below + above;
    if (sum < whole) {
      below = sum > 0.0 ? below * whole / sum : 0.5 * whole;
      above = whole - below;
    }
  }
};

class BspBuild {
 public:
  BspBuild(const std::vector<Triangle>& triangles, const BspTreeBuilder::Config& config, BspTree& tree)
      : triangles_(triangles),
        config_(config),
        tree_(tree),
        depth_limit_(BspTreeBuilder::depth_limit(config, triangles.size())),
        reference_budget_(BspTreeBuilder::kMaxReferencesPerTriangle * triangles.size() + 64),
        node_budget_(4 * reference_budget_ + 1),
        references_(triangles.size()) {}

  // Returns the peak bytes of scratch held at once.
  uint64_t run() {
    Refs refs;
    refs.reserve(triangles_.size());
    Dop root;
    root.lo.fill(kInf);
    root.hi.fill(-kInf);
    for (uint32_t t = 0; t < triangles_.size(); ++t) {
      const Dop e = triangle_extents(triangles_[t]);
      refs.push_back({t, e});
      for (uint32_t k = 0; k < kK; ++k) {
        root.lo[k] = std::min(root.lo[k], e.lo[k]);
        root.hi[k] = std::max(root.hi[k], e.hi[k]);
      }
    }
    track(static_cast<int64_t>(refs.capacity()));
    for (int axis = 0; axis < 3; ++axis) {
      tree_.bounds.lo[axis] = root.lo[axis];
      tree_.bounds.hi[axis] = root.hi[axis];
    }
    BspPolytope cell = BspPolytope::box(Vec3d(tree_.bounds.lo), Vec3d(tree_.bounds.hi));
    for (uint32_t k = 3; k < kK; ++k) {
      cell = cell.clipped(k, root.lo[k], false).clipped(k, root.hi[k], true);
    }
    node(std::move(refs), root, cell, 1);
    return static_cast<uint64_t>(peak_refs_) * sizeof(Ref) + kPolytopeBytes;
  }

 private:
  void track(int64_t delta) {
    live_refs_ += delta;
    peak_refs_ = std::max(peak_refs_, live_refs_);
  }
  void release(Refs& refs) {
    track(-static_cast<int64_t>(refs.capacity()));
    Refs().swap(refs);
  }

  double cost(double below_area, double above_area, double area, std::size_t below, std::size_t above) const {
    double c = config_.traversal_cost +
               config_.intersection_cost *
                   (below_area * static_cast<double>(below) + above_area * static_cast<double>(above)) / area;
    if (below == 0 || above == 0) c *= 1.0 - config_.empty_bonus;
    return c;
  }

  void consider(BspSplit& best, uint32_t k, float s, const AreaModel& model, double area, std::size_t below,
                std::size_t above) const {
    if (!(model.lo < s && s < model.hi)) return;
    // Empty space is cut off along the axes only: with the empty bonus, each
    // sliver cut from a cell's corners by a diagonal plane (every cut changes
    // the cell's extent along the other directions, which opens the next)
    // would look cheaper than a leaf, and the cuts would go on to the depth
    // limit.
    if ((below == 0 || above == 0) && k >= 3) return;
    double below_area, above_area;
    model.at(s, below_area, above_area);
    const double c = cost(below_area, above_area, area, below, above);
    if (c < best.cost) best = {static_cast<int>(k), s, c};
  }

  // Every reference's extent ends as candidates, counted exactly: a
  // reference goes below when it ends at or before the plane, above when it
  // starts at or after it (and does not end at it), else to both.
  void exact_candidates(const Refs& refs, uint32_t k, const AreaModel& model, double area,
                        BspSplit& best) const {
    for (const Ref& candidate : refs) {
      for (const float s : {candidate.extents.lo[k], candidate.extents.hi[k]}) {
        std::size_t below = 0, above = 0;
        for (const Ref& r : refs) {
          const bool only_below = r.extents.hi[k] <= s;
          below += only_below || r.extents.lo[k] < s;
          above += !only_below;
        }
        consider(best, k, s, model, area, below, above);
      }
    }
  }

  void binned_candidates(const Refs& refs, uint32_t k, const AreaModel& model, double area,
                         BspSplit& best) const {
    constexpr uint32_t kBins = BspTreeBuilder::kBins;
    std::array<uint32_t, kBins> starts{}, ends{};
    const double scale = kBins / (model.hi - model.lo);
    const auto bin = [&](float x) {
      const double b = (static_cast<double>(x) - model.lo) * scale;
      return b <= 0.0 ? 0u : std::min(kBins - 1, static_cast<uint32_t>(b));
    };
    for (const Ref& r : refs) {
      ++starts[bin(r.extents.lo[k])];
      ++ends[bin(r.extents.hi[k])];
    }
    std::size_t below = 0, above = refs.size();
    for (uint32_t i = 1; i < kBins; ++i) {
      below += starts[i - 1];
      above -= ends[i - 1];
      const auto s = static_cast<float>(model.lo + (model.hi - model.lo) * i / kBins);
      consider(best, k, s, model, area, below, above);
    }
  }

  BspSplit best_split(const Refs& refs, const Dop& dop, const BspPolytope& cell) const {
    BspSplit best;
    const double area = cell.area();
    if (!(area > 0.0)) return best;
    for (uint32_t k = 0; k < config_.directions; ++k) {
      AreaModel model(cell, k, area);
      // Candidates strictly inside the cell's interval too: the polytope's
      // rounding may reach a hair past it, and a plane on the cell's face
      // would make a child of the same cell (with the empty bonus, forever).
      model.lo = std::max(model.lo, double{dop.lo[k]});
      model.hi = std::min(model.hi, double{dop.hi[k]});
      if (!(model.hi > model.lo)) continue;
      if (refs.size() <= BspTreeBuilder::kExactCandidates) {
        exact_candidates(refs, k, model, area, best);
      } else {
        binned_candidates(refs, k, model, area, best);
      }
    }
    return best;
  }

  void leaf(const Refs& refs, uint32_t index) {
    const auto first = static_cast<uint32_t>(tree_.refs.size());
    for (const Ref& r : refs) tree_.refs.push_back(r.triangle);
    tree_.nodes[index] = BspNode::leaf(first, static_cast<uint32_t>(refs.size()));
  }

  void node(Refs refs, const Dop& cell, const BspPolytope& polytope, uint32_t depth) {
    const auto index = static_cast<uint32_t>(tree_.nodes.size());
    tree_.nodes.emplace_back();
    const std::size_t n = refs.size();
    BspSplit split;
    if (n > 0 && depth < depth_limit_ && tree_.nodes.size() + 2 <= node_budget_ && !polytope.empty()) {
      split = best_split(refs, cell, polytope);
      if (!(split.cost < config_.intersection_cost * static_cast<double>(n))) split.direction = -1;
    }
    if (split.direction < 0) {
      leaf(refs, index);
      release(refs);
      return;
    }
    const auto k = static_cast<uint32_t>(split.direction);
    const float s = split.position;
    Dop lower = cell, upper = cell;
    lower.hi[k] = std::min(lower.hi[k], s);
    upper.lo[k] = std::max(upper.lo[k], s);
    // Sized exactly first, so that the bound on scratch holds.
    std::size_t n_below = 0, n_above = 0;
    for (const Ref& r : refs) {
      n_below += r.extents.lo[k] < s || r.extents.hi[k] <= s;
      n_above += r.extents.hi[k] > s;
    }
    if (references_ + n_below + n_above - n > reference_budget_) {
      // Over budget: this node stays a leaf (the tree's size is bounded).
      leaf(refs, index);
      release(refs);
      return;
    }
    references_ += n_below + n_above - n;
    Refs below, above;
    below.reserve(n_below);
    above.reserve(n_above);
    track(static_cast<int64_t>(n_below + n_above));
    for (const Ref& r : refs) {
      if (r.extents.hi[k] <= s) {
        below.push_back(r);
      } else if (r.extents.lo[k] >= s) {
        above.push_back(r);
      } else {
        below.push_back(r);
        narrow_to(below.back(), triangles_[r.triangle], lower);
        above.push_back(r);
        narrow_to(above.back(), triangles_[r.triangle], upper);
      }
    }
    assert(below.size() == n_below && above.size() == n_above);
    release(refs);
    const BspPolytope lower_polytope = polytope.clipped(k, s, true);
    node(std::move(below), lower, lower_polytope, depth + 1);
    const auto above_index = static_cast<uint32_t>(tree_.nodes.size());
    const BspPolytope upper_polytope = polytope.clipped(k, s, false);
    node(std::move(above), upper, upper_polytope, depth + 1);
    tree_.nodes[index] = BspNode::inner(k, s, above_index);
  }

  const std::vector<Triangle>& triangles_;
  const BspTreeBuilder::Config& config_;
  BspTree& tree_;
  uint32_t depth_limit_;
  uint64_t reference_budget_, node_budget_;
  uint64_t references_;
  int64_t live_refs_ = 0, peak_refs_ = 0;
};

}  // namespace

Status BspTreeBuilder::Config::validate() const {
  OUTCORE_RETURN_IF_ERROR(SplitTreeCosts::validate("bsp", kMaxBspDepth));
  if (directions != 3 && directions != 7 && directions != 13) {
    return invalid_argument("bsp: directions must be 3, 7 or 13, got " + std::to_string(directions));
  }
  return Status::Ok();
}

uint32_t BspTreeBuilder::depth_limit(const Config& config, uint64_t n) {
  return config.depth_limit(n, kMaxBspDepth);
}

uint64_t BspTreeBuilder::tree_bytes_bound(uint64_t n) {
  const uint64_t references = kMaxReferencesPerTriangle * n + 64;
  const uint64_t nodes = 4 * references + 1;
  return nodes * sizeof(BspNode) + references * sizeof(uint32_t) +
         n * (sizeof(Triangle) + sizeof(BvhHitRecord));
}

// References held at once: the pending subtrees' (disjoint, so within the
// reference budget) plus, while a node splits, its own list and its
// children's: at most three times the budget; and the polytopes on the path.
uint64_t BspTreeBuilder::peak_bytes_bound(uint64_t n) {
  const uint64_t references = kMaxReferencesPerTriangle * n + 64;
  return 3 * references * sizeof(Ref) + kPolytopeBytes;
}

BspTreeBuilder::Result BspTreeBuilder::build(std::vector<Triangle> triangles,
                                             const std::vector<TriangleId>& ids, const Config& config) {
  assert(config.validate().ok());
  assert(ids.size() == triangles.size());
  Result result;
  BspTree& tree = result.tree;
  if (triangles.empty()) return result;
  tree.adopt_triangles(std::move(triangles), ids);
  BspBuild build(tree.triangles, config, tree);
  result.peak_bytes = build.run();
  tree.trim();
  return result;
}

}  // namespace outcore
