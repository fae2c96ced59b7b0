// Ray packets for the wide BVH: closest hits of up to V::kWidth rays that
// leave one origin with the same watertight axis permutation (a camera's
// rays, in pixel order) traced together, one ray per lane: each node's and
// each triangle's data are fetched once for the packet, and the walk is
// decided once for it. Rays that do not form such a run take the single-ray
// walk (wide_bvh_kernels.h). Compiled like that header, once per lane type.
//
// At each node the packet first tests all eight children at once against two
// bounds of the whole packet (an interval bound of the lanes' slab distances
// and a slope pyramid around the dominant axis, packet_children()); only the
// children that pass take the lane-by-lane box test, and children large
// against the lanes' spread skip it and take the packet's lanes. Once at
// most kSingleRayLanes lanes enter a subtree, each walks it as a single ray
// (wide_bvh_kernels.h), eight boxes per test instead of one.
//
// Exact as the single-ray walk: the packet bounds only drop children no lane
// can enter; a lane's box test is the single-ray walk's conservative slab
// test (margin kBoxMargin, a NaN slab distance constrains nothing); a lane's
// triangle test is the scalar watertight test's IEEE operations in its order
// (the shared permutation makes the vertex rows the same for every lane), so
// t, u, v are bitwise the scalar test's, and a lane taken into a box it does
// not enter finds nothing there that its own walk would not. Ties go by
// hit_is_better; the answers are bitwise the single-ray walk's (tested).
//
// Thread-safety: pure functions over an immutable WideBvhView.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/accel/bvh/wide_bvh_kernels.h"
#include "core/accel/bvh/wide_bvh_stepped_kernels.h"

namespace outcore::wide_kernels {

// A box whose smallest side exceeds this many times the lanes' spread at
// its entry takes the whole packet without a lane-by-lane box test (measured:
// 0.5 sped the bunny's camera rays up by ~14 % and left the city's and the
// sparse scene's, whose packets are looser, as they were).
inline constexpr float kLaneTestFootprints = 0.5f;

// A subtree that at most this many of a packet's lanes enter is walked by
// each of them as a single ray (measured 1..8: 4, half the packet, was the
// best for the bunny's, the city's and the sparse scene's camera rays;
// 8, no packets, was 2x slower on the bunny).
inline constexpr int kSingleRayLanes = 4;

// Up to V::kWidth rays traced as one packet.
template <class V>
class WatertightPacket {
 public:
  using F = typename V::F;
  static constexpr uint32_t kWidth = V::kWidth;

  // Rays rays[ids[0..count)], which share the permutation of rays[ids[0]].
  WatertightPacket(const Ray* rays, const uint32_t* ids, uint32_t count, Hit* hits)
      : rays_(rays), hits_(hits) {
    axes_ = WatertightTriangleTest::axes(rays[ids[0]].direction);
    alignas(32) float o[3][kWidth], inv[3][kWidth], po[3][kWidth], s[3][kWidth], tnear[kWidth];
    for (uint32_t lane = 0; lane < kWidth; ++lane) {
      const uint32_t id = ids[lane < count ? lane : 0];
      const Ray& ray = rays[id];
      const WatertightTriangleTest::Prepared p = WatertightTriangleTest::prepare(ray);
      for (int a = 0; a < 3; ++a) {
        o[a][lane] = ray.origin[a];
        inv[a][lane] = 1.0f / ray.direction[a];
      }
      po[0][lane] = p.ox;
      po[1][lane] = p.oy;
      po[2][lane] = p.oz;
      s[0][lane] = p.sx;
      s[1][lane] = p.sy;
      s[2][lane] = p.sz;
      tnear[lane] = ray.tnear;
      ids_[lane] = id;
      direction_[lane] = ray.direction;
      const Hit& best = hits[id];
      tmax_[lane] = ray.tfar < best.t ? ray.tfar : best.t;
      if (lane < count && tmax_[lane] > ray.tnear) {
        active_ |= 1u << lane;
      } else {
        tmax_[lane] = -std::numeric_limits<float>::infinity();  // out of packet_children()'s bound
      }
    }
    for (int a = 0; a < 3; ++a) {
      origin_[a] = V::load(o[a]);
      inverse_[a] = V::load(inv[a]);
      permuted_origin_[a] = V::load(po[a]);
      shear_[a] = V::load(s[a]);
    }
    tnear_ = V::load(tnear);
    prepare_packet_bound(o, inv, tnear);
  }

  // Over one tree (a set of one) or the trees of a set, walking its top
  // level with the packet.
  void trace_set(const WideBvhSetView& set) {
    if (active_ == 0) return;
    if (set.trees.size() == 1) return trace_lanes(set.trees[0], active_);
    walk(
        set.top, active_,
        [&](uint32_t tree, uint32_t, uint32_t lanes) { trace_lanes(set.trees[tree], lanes); },
        [&](uint32_t tree) { prefetch_lines(set.trees[tree].nodes.data(), sizeof(WideBvhNode)); },
        [](uint32_t, uint32_t) { return false; });
  }

  // Completes each lane's best (barycentrics, normal).
  void finish() {
    for (uint32_t lane = 0; lane < kWidth; ++lane) {
      if (found_packet_[lane] == nullptr) continue;
      Hit& best = hits_[ids_[lane]];
      best.u = found_hit_[lane].u;
      best.v = found_hit_[lane].v;
      best.normal = found_packet_[lane]->triangle(found_slot_lane_[lane]).unit_normal();
    }
  }

 private:
  void trace_lanes(const WideBvhView& tree, uint32_t lanes) {
    walk(
        tree.nodes, lanes,
        [&](uint32_t first, uint32_t count, uint32_t leaf_lanes) {
          test_leaf(tree.packets.data(), first, count, leaf_lanes);
        },
        [](uint32_t) {},
        [&](uint32_t node, uint32_t node_lanes) {
          if (__builtin_popcount(node_lanes) > kSingleRayLanes) return false;
          for (uint32_t bits = node_lanes; bits != 0; bits &= bits - 1) {
            trace_single(tree, node, static_cast<uint32_t>(__builtin_ctz(bits)));
          }
          return true;
        });
  }

  // One lane's walk of the subtree at `node` as a single ray: eight children
  // tested at once for one ray cost less than one child for the packet's
  // lanes once the lanes have parted. Its best hit and tmax carry over.
  void trace_single(const WideBvhView& tree, uint32_t node, uint32_t lane) {
    Hit& best = hits_[ids_[lane]];
    ClosestHitSearch<V, WatertightLanes<V>> search(rays_[ids_[lane]], best);
    if (!search.active()) return;
    search.search(tree, node);
    if (search.finish()) found_packet_[lane] = nullptr;  // best is complete; a later packet hit redoes it
    tmax_[lane] = search.tmax();
  }

  // The packet's walk of `nodes` for `lanes`, nearest entry first:
  // leaf(ref, count, lanes) for each leaf some lane may still hit;
  // alone(node, lanes) may take over an inner node's subtree (true).
  template <class Leaf, class PrefetchLeaf, class Alone>
  void walk(std::span<const WideBvhNode> nodes, uint32_t lanes, Leaf&& leaf, PrefetchLeaf&& prefetch_leaf,
            Alone&& alone) {
    if (nodes.empty()) return;
    struct Item {
      uint32_t ref, triangles, lanes;
      float entry;  // the smallest entry of its lanes
    };
    std::array<Item, (kWideBvhWidth - 1) * kMaxBvhDepth + kWideBvhWidth> stack;
    uint32_t top = 0;
    stack[top++] = {0, 0, lanes, -std::numeric_limits<float>::infinity()};
    while (top > 0) {
      const Item item = stack[--top];
      if (!may_matter(item.lanes, item.entry)) continue;
      if (item.triangles != 0) {
        leaf(item.ref, item.triangles, item.lanes);
        continue;
      }
      if (alone(item.ref, item.lanes)) continue;
      const WideBvhNode& node = nodes[item.ref];
      const uint32_t base = top;
      alignas(32) float entries[kWideBvhWidth];
      uint32_t whole_packet;
      for (uint32_t bits = packet_children(node, entries, whole_packet); bits != 0; bits &= bits - 1) {
        const auto k = static_cast<uint32_t>(__builtin_ctz(bits));
        float entry = entries[k];
        uint32_t hit_lanes = item.lanes;
        if (!(whole_packet >> k & 1u)) {
          hit_lanes = box_lanes(node, k, item.lanes, entry);
          if (hit_lanes == 0) continue;
        }
        const Item child{node.child[k], node.leaf_triangles[k], hit_lanes, entry};
        if (child.triangles == 0) {
          prefetch_lines(&nodes[child.ref], sizeof(WideBvhNode));
        } else {
          prefetch_leaf(child.ref);
        }
        uint32_t j = top++;
        for (; j > base && stack[j - 1].entry < child.entry; --j) stack[j] = stack[j - 1];
        stack[j] = child;
      }
    }
  }

  // The packet-wide bounds' inputs (packet_children), from the lanes' rays.
  void prepare_packet_bound(const float (&o)[3][kWidth], const float (&inv)[3][kWidth],
                            const float (&tnear)[kWidth]) {
    tnear_lo_ = tnear[0];
    for (uint32_t lane = 1; lane < kWidth; ++lane) tnear_lo_ = std::min(tnear_lo_, tnear[lane]);
    // Interval bound: per axis the lanes' smallest and largest inverse
    // direction, where all are finite and so is the origin.
    for (int a = 0; a < 3; ++a) {
      float lo = inv[a][0], hi = inv[a][0];
      bool finite = std::isfinite(o[a][0]);
      for (uint32_t lane = 0; lane < kWidth; ++lane) {
        finite = finite && std::isfinite(inv[a][lane]);
        lo = std::min(lo, inv[a][lane]);
        hi = std::max(hi, inv[a][lane]);
      }
      if (!finite) continue;
      bounded_axes_[bounded_count_] = a;
      inverse_lo_[bounded_count_] = V::set1(lo);
      inverse_hi_[bounded_count_] = V::set1(hi);
      ++bounded_count_;
    }
    // Slope bound: the lanes' slopes over the shared dominant axis kz
    // (|slope| <= 1), where they are finite, for segments that start at
    // t >= 0.
    const int kz = axes_.kz;
    const float dz = direction_[0][kz];
    sloped_ = tnear_lo_ >= 0.0f && dz != 0.0f && std::isfinite(o[kz][0]);
    forward_ = dz > 0.0f;
    for (int j = 0; j < 2; ++j) {
      const int a = (kz + 1 + j) % 3;
      float lo = direction_[0][a] / dz, hi = lo;
      for (uint32_t lane = 1; lane < kWidth; ++lane) {
        const float slope = direction_[lane][a] / direction_[lane][kz];
        lo = std::min(lo, slope);
        hi = std::max(hi, slope);
      }
      sloped_ = sloped_ && std::isfinite(lo) && std::isfinite(hi) && std::isfinite(o[a][0]);
      slope_axis_[j] = a;
      slope_lo_[j] = V::set1(lo);
      slope_hi_[j] = V::set1(hi);
    }
    // How far apart two lanes' rays may be per unit of t: twice the largest
    // chord from the first lane's unit direction, times the longest direction.
    const float first_length = length(direction_[0]);
    float min_cos = 1.0f, longest = first_length;
    for (uint32_t lane = 1; lane < kWidth; ++lane) {
      const float len = length(direction_[lane]);
      min_cos = std::min(min_cos, dot(direction_[0], direction_[lane]) / (first_length * len));
      longest = std::max(longest, len);
    }
    const float spread = 2.0f * std::sqrt(std::max(0.0f, 2.0f * (1.0f - min_cos))) * longest;
    lane_test_size_ = V::set1(spread * kLaneTestFootprints);
  }

  // The children of `node` that some lane may enter (its bit set), tested
  // all eight at once against two bounds of the whole packet, so that the
  // lane-by-lane test runs only for these; entries[k]: a lower bound of
  // where the lanes enter child k. `whole_packet` gets the children so large
  // against the lanes' spread at that entry that they take the packet's
  // lanes without a lane-by-lane test (most lanes enter such a box; a lane
  // that does not costs only its share of the SIMD triangle tests, which
  // decide exactly).
  //
  // Interval bound, sound because the lanes share one origin: a lane's slab
  // distance fl(fl(plane - o) * inverse) is monotonic in its inverse (and so
  // is rounding), so the products with the lanes' extreme inverses bound
  // every lane's near and far distance on that axis; min(tnear) and
  // max(tmax) bound their segments; the widening is monotonic. A lane that
  // passes its own box test passes this one. A NaN plane distance
  // constrains nothing, as in the lane test. Loose where a direction
  // component is small against the lanes' spread, hence the slope bound.
  uint32_t packet_children(const WideBvhNode& node, float* entries, uint32_t& whole_packet) const {
    float tmax_hi = tmax_[0];
    for (uint32_t lane = 1; lane < kWidth; ++lane) tmax_hi = std::max(tmax_hi, tmax_[lane]);
    const F inf = V::set1(std::numeric_limits<float>::infinity());
    const F minus_inf = V::set1(-std::numeric_limits<float>::infinity());
    const F zero = V::set1(0.0f);
    const F down = V::set1(bvh_detail::kWidenDown), up = V::set1(bvh_detail::kWidenUp);
    uint32_t mask = 0;
    whole_packet = 0;
    for (uint32_t group = 0; group < kWideBvhWidth; group += kWidth) {
      F lo = V::set1(tnear_lo_), hi = V::set1(tmax_hi);
      for (uint32_t b = 0; b < bounded_count_; ++b) {
        const int a = bounded_axes_[b];
        const F d_lo = V::sub(V::load(&node.lo[a][group]), origin_[a]);
        const F d_hi = V::sub(V::load(&node.hi[a][group]), origin_[a]);
        const F p0 = V::mul(d_lo, inverse_lo_[b]), p1 = V::mul(d_lo, inverse_hi_[b]);
        const F p2 = V::mul(d_hi, inverse_lo_[b]), p3 = V::mul(d_hi, inverse_hi_[b]);
        const F nan = V::bit_or(V::neq(d_lo, d_lo), V::neq(d_hi, d_hi));
        const F near = V::blend(V::min(V::min(p0, p1), V::min(p2, p3)), minus_inf, nan);
        const F far = V::blend(V::max(V::max(p0, p1), V::max(p2, p3)), inf, nan);
        lo = V::max(near, lo);
        hi = V::min(far, hi);
      }
      lo = V::min(V::mul(lo, down), V::mul(lo, up));
      hi = V::max(V::mul(hi, down), V::mul(hi, up));
      V::store(entries + group, lo);
      uint32_t pass = V::mask(V::le(lo, hi));
      if (sloped_) pass &= slope_children(node, group);
      mask |= pass << group;
      F size = V::sub(V::load(&node.hi[0][group]), V::load(&node.lo[0][group]));
      for (int a = 1; a < 3; ++a)
        size = V::min(size, V::sub(V::load(&node.hi[a][group]), V::load(&node.lo[a][group])));
      whole_packet |= V::mask(V::gt(size, V::mul(V::max(lo, zero), lane_test_size_))) << group;
    }
    return mask & node.child_mask();
  }

  // Of the V::kWidth children from `group`, those the pyramid of the lanes'
  // slopes may touch: along the dominant axis z the segments cover w = z - oz
  // of one sign (t >= 0), and on a side axis x they reach x - ox = slope * w;
  // a child whose x range lies beyond every (slope, w) product of its w
  // range on either side axis is out of every lane's reach. The margin, a
  // relative 2^-16 of the box's extent from the origin, covers the rounding
  // of the slopes and products and how far off its ray a float triangle test
  // may still report a hit (about 2^-22 of the vertices' distance from the
  // origin in the watertight test's sheared coordinates).
  uint32_t slope_children(const WideBvhNode& node, uint32_t group) const {
    const int kz = axes_.kz;
    const F zero = V::set1(0.0f);
    F w0 = V::sub(V::load(&node.lo[kz][group]), origin_[kz]);
    F w1 = V::sub(V::load(&node.hi[kz][group]), origin_[kz]);
    const F extent = V::max(abs_of(w0), abs_of(w1));  // of the whole box: vertices behind count too
    F miss;                                           // behind the origin (NaN: not known to miss)
    if (forward_) {
      miss = V::lt(w1, zero);
      w0 = V::max(w0, zero);
    } else {
      miss = V::gt(w0, zero);
      w1 = V::min(w1, zero);
    }
    for (int j = 0; j < 2; ++j) {
      const int a = slope_axis_[j];
      const F x0 = V::sub(V::load(&node.lo[a][group]), origin_[a]);
      const F x1 = V::sub(V::load(&node.hi[a][group]), origin_[a]);
      const F p0 = V::mul(slope_lo_[j], w0), p1 = V::mul(slope_lo_[j], w1);
      const F p2 = V::mul(slope_hi_[j], w0), p3 = V::mul(slope_hi_[j], w1);
      const F reach_lo = V::min(V::min(p0, p1), V::min(p2, p3));
      const F reach_hi = V::max(V::max(p0, p1), V::max(p2, p3));
      const F margin = V::mul(V::max(extent, V::max(abs_of(x0), abs_of(x1))), V::set1(0x1p-16f));
      miss = V::bit_or(miss, V::lt(V::add(reach_hi, margin), x0));
      miss = V::bit_or(miss, V::gt(V::sub(reach_lo, margin), x1));
    }
    return ~V::mask(miss) & ((1u << kWidth) - 1u);
  }

  static F abs_of(F x) { return V::max(x, V::sub(V::set1(0.0f), x)); }

  // Whether any of `lanes` can still find a hit at or beyond `entry`.
  bool may_matter(uint32_t lanes, float entry) const {
    for (uint32_t bits = lanes; bits != 0; bits &= bits - 1) {
      if (entry <= tmax_[__builtin_ctz(bits)]) return true;
    }
    return false;
  }

  // The lanes of `lanes` whose segment may touch child k's box; entry: the
  // smallest lower bound of where they enter.
  uint32_t box_lanes(const WideBvhNode& node, uint32_t k, uint32_t lanes, float& entry) const {
    const F inf = V::set1(std::numeric_limits<float>::infinity());
    const F minus_inf = V::set1(-std::numeric_limits<float>::infinity());
    F lo = tnear_, hi = V::load_unaligned(tmax_);
    for (int a = 0; a < 3; ++a) {
      const F t0 = V::mul(V::sub(V::set1(node.lo[a][k]), origin_[a]), inverse_[a]);
      const F t1 = V::mul(V::sub(V::set1(node.hi[a][k]), origin_[a]), inverse_[a]);
      // Either distance NaN: the line lies in the slab's plane, no constraint.
      const F nan = V::bit_or(V::neq(t0, t0), V::neq(t1, t1));
      const F near = V::blend(V::min(t0, t1), minus_inf, nan);
      const F far = V::blend(V::max(t0, t1), inf, nan);
      lo = V::max(near, lo);
      hi = V::min(far, hi);
    }
    const F down = V::set1(bvh_detail::kWidenDown), up = V::set1(bvh_detail::kWidenUp);
    lo = V::min(V::mul(lo, down), V::mul(lo, up));
    hi = V::max(V::mul(hi, down), V::mul(hi, up));
    const uint32_t hit = lanes & V::mask(V::le(lo, hi));
    if (hit != 0) {
      alignas(32) float entries[kWidth];
      V::store(entries, lo);
      entry = std::numeric_limits<float>::infinity();
      for (uint32_t bits = hit; bits != 0; bits &= bits - 1)
        entry = std::min(entry, entries[__builtin_ctz(bits)]);
    }
    return hit;
  }

  void test_leaf(const TrianglePacket* packets, uint32_t first, uint32_t count, uint32_t lanes) {
    for (uint32_t slot = first; slot < first + count; ++slot) {
      const TrianglePacket& packet = packets[slot / kPacketLanes];
      const uint32_t lane_of_slot = slot % kPacketLanes;
      test_triangle(packet, lane_of_slot, lanes);
    }
  }

  // The watertight test of one triangle against every lane, as the scalar
  // test computes it for each ray.
  void test_triangle(const TrianglePacket& packet, uint32_t slot_lane, uint32_t lanes) {
    const auto vertex = [&](int v, int axis) { return V::set1(packet.coord[3 * v + axis][slot_lane]); };
    WatertightLaneHits<V> found;
    const uint32_t pass = watertight_lanes<V>(vertex, axes_, permuted_origin_, shear_, lanes, tnear_,
                                              V::load_unaligned(tmax_), found);
    if (pass == 0) return;
    const Triangle tri = packet.triangle(slot_lane);
    const uint32_t geometry_id = packet.geometry_id[slot_lane], primitive_id = packet.primitive_id[slot_lane];
    for (uint32_t bits = pass; bits != 0; bits &= bits - 1) {
      const auto lane = static_cast<uint32_t>(__builtin_ctz(bits));
      if (WatertightTriangleTest::in_plane(direction_[lane], tri)) continue;
      Hit& best = hits_[ids_[lane]];
      if (!hit_is_better(found.t[lane], geometry_id, primitive_id, best)) continue;
      best.t = found.t[lane];
      best.geometry_id = geometry_id;
      best.primitive_id = primitive_id;
      found_packet_[lane] = &packet;
      found_slot_lane_[lane] = slot_lane;
      found_hit_[lane] = found.hit(lane);
      tmax_[lane] = found.t[lane];  // inclusive: a tie may still win on its id
    }
  }

  const Ray* rays_;
  Hit* hits_;
  WatertightTriangleTest::Axes axes_{};
  uint32_t active_ = 0;
  uint32_t ids_[kWidth];
  Vec3f direction_[kWidth];
  alignas(32) float tmax_[kWidth];
  F origin_[3], inverse_[3], permuted_origin_[3], shear_[3], tnear_;
  // packet_children()'s bounds: the interval bound's axes and inverse
  // extremes; the slope bound's side axes and slope extremes; the size
  // per unit of entry above which a box takes the whole packet.
  F inverse_lo_[3], inverse_hi_[3];
  int bounded_axes_[3] = {};
  uint32_t bounded_count_ = 0;
  float tnear_lo_ = 0;
  F slope_lo_[2], slope_hi_[2];
  int slope_axis_[2] = {};
  bool sloped_ = false, forward_ = true;
  F lane_test_size_;
  const TrianglePacket* found_packet_[kWidth] = {};
  uint32_t found_slot_lane_[kWidth] = {};
  TriangleHit found_hit_[kWidth] = {};
};

// The length of the run of rays from ray_ids[start] that may go as one
// packet: the same origin, bitwise, and the same watertight permutation.
template <uint32_t kWidth>
inline uint32_t packet_run(std::span<const uint32_t> ray_ids, std::size_t start, const Ray* rays) {
  const Ray& first = rays[ray_ids[start]];
  // Incoherent rays part at the first comparison, before any division.
  if (start + 1 >= ray_ids.size() || !(rays[ray_ids[start + 1]].origin == first.origin)) return 1;
  const WatertightTriangleTest::Axes axes = WatertightTriangleTest::axes(first.direction);
  uint32_t count = 1;
  while (count < kWidth && start + count < ray_ids.size()) {
    const Ray& next = rays[ray_ids[start + count]];
    if (!(next.origin == first.origin) || !(WatertightTriangleTest::axes(next.direction) == axes)) break;
    ++count;
  }
  return count;
}

// Closest hits with the watertight test: packets where rays form runs of at
// least half a packet, single rays elsewhere, gathered and walked kWalks at a
// time when the set is one tree (wide_bvh_stepped_kernels.h); over one tree
// (a set of one, without top level) or a brick set.
template <class V, int kWalks>
void intersect_watertight_coherent(const WideBvhSetView& set, std::span<const uint32_t> ray_ids,
                                   const Ray* rays, Hit* hits) {
  constexpr uint32_t kWidth = V::kWidth;
  constexpr uint32_t kGathered = 64;
  std::array<uint32_t, kGathered> singles;
  uint32_t single_count = 0;
  const auto trace_singles = [&] {
    const std::span<const uint32_t> ids(singles.data(), single_count);
    if (set.trees.size() == 1) {
      intersect_rays<V, WatertightLanes<V>, kWalks>(set.trees[0], ids, rays, hits);
    } else {
      intersect_set<V, WatertightLanes<V>>(set, ids, rays, hits);
    }
    single_count = 0;
  };
  std::size_t i = 0;
  while (i < ray_ids.size()) {
    const uint32_t run = packet_run<kWidth>(ray_ids, i, rays);
    if (run * 2 < kWidth) {
      for (uint32_t k = 0; k < run; ++k) {
        singles[single_count++] = ray_ids[i + k];
        if (single_count == kGathered) trace_singles();
      }
    } else {
      WatertightPacket<V> packet(rays, ray_ids.data() + i, run, hits);
      packet.trace_set(set);
      packet.finish();
    }
    i += run;
  }
  if (single_count > 0) trace_singles();
}

}  // namespace outcore::wide_kernels
