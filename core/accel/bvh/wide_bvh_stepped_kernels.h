// Closest hits and occlusion of many rays in one wide BVH with several
// rays' walks interleaved: each walk advances by one node or one leaf in
// turn. A single ray's walk is a chain of dependent steps (fetch a node, test
// its boxes, pick the next), bound by memory latency and branch outcomes; a
// second and third chain give the core independent work while one waits. Measured
// (docs/BENCHMARKS.md, issue 23): warm incoherent batches of the sparse scene
// and the city take ~0.87-0.90x the time with three walks, where every brick
// visit starts cold in the brick's structure; on the bunny, whose one tree
// stays cached, two take 0.98x the time and three ~1.08x. Occlusion of the
// sparse scene's incoherent rays: 0.90x with three.
//
// The answers are the single walk's (wide_bvh_kernels.h), bitwise: a ray's
// steps are the same in the same order, only other rays' steps come between.
// A ray listed twice is searched twice at once, and still answered right
// (SteppedWalk::finish).
//
// Compiled like wide_bvh_kernels.h, once per lane type.
//
// Thread-safety: pure functions over an immutable WideBvhView.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>

#include "core/accel/bvh/wide_bvh_kernels.h"

namespace outcore::wide_kernels {

// One ray's walk of one tree (traverse_nodes), one step per call: its
// closest hit (as ClosestHitSearch), or with kAnyHit whether it hits
// anything (as AnyHitSearch: the walk stops at the first hit).
template <class V, class Lanes, bool kAnyHit>
class SteppedWalk {
 public:
  // Starts the closest hit of `ray` over (tnear, min(tfar, best.t)]; false
  // when that is empty (nothing to search).
  bool start(const Ray& ray, Hit& best) {
    static_assert(!kAnyHit);
    best_ = &best;
    found_packet_ = nullptr;
    return begin(ray, ray.tfar < best.t ? ray.tfar : best.t);
  }
  // Starts the occlusion test of `ray`; false for a ray already occluded.
  bool start(const Ray& ray, uint8_t& occluded) {
    static_assert(kAnyHit);
    occluded_ = &occluded;
    return occluded == 0 && begin(ray, ray.tfar);
  }

  // Tests one node's boxes, or one leaf; false when the walk is over.
  bool step(const WideBvhView& tree) {
    if (index_ != kNoNode) {
      visit_node(tree);
      return true;
    }
    while (top_ > 0) {
      const Item item = stack_[--top_];
      if (item.entry > tmax_) continue;
      if (item.triangles == 0) {
        index_ = item.ref;
      } else if (test_leaf(tree.packets.data(), item.ref, item.triangles)) {
        top_ = 0;  // occluded: done
        return false;
      }
      return true;
    }
    return false;
  }

  // Completes best (barycentrics, normal) when the hit this walk found is
  // still best (the same ray walked twice at once would otherwise mix two).
  void finish() {
    if (kAnyHit || found_packet_ == nullptr) return;
    if (best_->t != found_hit_.t || best_->geometry_id != found_packet_->geometry_id[found_lane_] ||
        best_->primitive_id != found_packet_->primitive_id[found_lane_]) {
      return;
    }
    best_->u = found_hit_.u;
    best_->v = found_hit_.v;
    best_->normal = found_packet_->triangle(found_lane_).unit_normal();
  }

 private:
  static constexpr uint32_t kNoNode = ~0u;
  struct Item {
    uint32_t ref;        // node index, or a leaf's first slot
    uint32_t triangles;  // 0 for a node, else the leaf's count
    float entry;
  };

  // As traverse_nodes: one inner child is entered at once; otherwise the
  // children go on the stack nearest on top, each fetched ahead.
  void visit_node(const WideBvhView& tree) {
    const WideBvhNode& node = tree.nodes[index_];
    index_ = kNoNode;
    alignas(32) float entry[kWideBvhWidth];
    const uint32_t mask = node_box_mask<V>(node, box_, ray_->tnear, tmax_, entry);
    if (mask == 0) return;
    if ((mask & (mask - 1)) == 0 && (node.inner_mask & mask) != 0) {
      index_ = node.child[__builtin_ctz(mask)];
      prefetch_lines(&tree.nodes[index_], sizeof(WideBvhNode));
      return;
    }
    for (uint32_t bits = mask; bits != 0; bits &= bits - 1) {
      const auto k = static_cast<uint32_t>(__builtin_ctz(bits));
      const Item item{node.child[k], node.leaf_triangles[k], entry[k]};
      if (item.triangles == 0) {
        prefetch_lines(&tree.nodes[item.ref], sizeof(WideBvhNode));
      } else {
        prefetch_lines(&tree.packets[item.ref / kPacketLanes], sizeof(TrianglePacket));
      }
      stack_[top_ + push_position<V>(entry, mask, k)] = item;
    }
    top_ += static_cast<uint32_t>(__builtin_popcount(mask));
  }

  bool begin(const Ray& ray, float tmax) {
    ray_ = &ray;
    box_ = BoxLanes<V>(ray);
    lanes_.emplace(ray);
    tmax_ = tmax;
    top_ = 0;
    index_ = 0;
    return tmax_ > ray.tnear;
  }

  // True to stop the walk: an any-hit query found its hit.
  bool test_leaf(const TrianglePacket* packets, uint32_t first, uint32_t count) {
    if constexpr (kAnyHit) {
      const bool hit = for_each_lane_group<V>(
          packets, first, count, [&](const TrianglePacket& packet, uint32_t lane, uint32_t valid) {
            for (uint32_t bits = lanes_->candidates(packet, lane, valid, ray_->tnear, tmax_); bits != 0;
                 bits &= bits - 1) {
              TriangleHit h;
              if (lanes_->accept(packet, lane, static_cast<uint32_t>(__builtin_ctz(bits)), h)) return true;
            }
            return false;
          });
      if (hit) *occluded_ = 1;
      return hit;
    }
    // As ClosestHitSearch's leaf test; never stops the walk.
    for_each_lane_group<V>(packets, first, count,
                           [&](const TrianglePacket& packet, uint32_t lane, uint32_t valid) {
                             for (uint32_t bits = lanes_->candidates(packet, lane, valid, ray_->tnear, tmax_);
                                  bits != 0; bits &= bits - 1) {
                               const auto bit = static_cast<uint32_t>(__builtin_ctz(bits));
                               TriangleHit h;
                               if (!lanes_->accept(packet, lane, bit, h)) continue;
                               const uint32_t geometry_id = packet.geometry_id[lane + bit];
                               const uint32_t primitive_id = packet.primitive_id[lane + bit];
                               if (!hit_is_better(h.t, geometry_id, primitive_id, *best_)) continue;
                               best_->t = h.t;
                               best_->geometry_id = geometry_id;
                               best_->primitive_id = primitive_id;
                               found_packet_ = &packet;
                               found_lane_ = lane + bit;
                               found_hit_ = h;
                               tmax_ = h.t;  // inclusive: a tie at h.t may still win on its id
                             }
                             return false;
                           });
    return false;
  }

  const Ray* ray_ = nullptr;
  Hit* best_ = nullptr;          // closest hit
  uint8_t* occluded_ = nullptr;  // any hit
  BoxLanes<V> box_{Ray{}};
  std::optional<Lanes> lanes_;
  float tmax_ = 0;
  const TrianglePacket* found_packet_ = nullptr;
  uint32_t found_lane_ = 0;
  TriangleHit found_hit_{};
  uint32_t index_ = kNoNode;  // the node to visit next, if any
  uint32_t top_ = 0;
  std::array<Item, (kWideBvhWidth - 1) * kMaxBvhDepth + kWideBvhWidth> stack_;
};

// Runs the walks that start_walk(walk, i) starts for each i in ray_ids
// (false: nothing to walk), kWalks at a time, interleaved step by step (1:
// one ray after the other).
template <int kWalks, class Walk, class StartWalk>
void interleave_walks(const WideBvhView& tree, std::span<const uint32_t> ray_ids, StartWalk&& start_walk) {
  static_assert(kWalks >= 1);
  if (tree.nodes.empty()) return;
  std::array<Walk, kWalks> walks;
  std::array<bool, kWalks> live{};
  std::size_t next = 0;
  const auto start_next = [&](Walk& walk) {
    while (next < ray_ids.size()) {
      if (start_walk(walk, ray_ids[next++])) return true;
    }
    return false;
  };
  int running = 0;
  for (int k = 0; k < kWalks; ++k) running += live[k] = start_next(walks[k]);
  while (running > 0) {
    for (int k = 0; k < kWalks; ++k) {
      if (!live[k] || walks[k].step(tree)) continue;
      walks[k].finish();
      live[k] = start_next(walks[k]);
      running -= !live[k];
    }
  }
}

// Closest hits of rays[ray_ids] in `tree`, kWalks walks interleaved.
template <class V, class Lanes, int kWalks>
void intersect_rays(const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) {
  using Walk = SteppedWalk<V, Lanes, false>;
  interleave_walks<kWalks, Walk>(tree, ray_ids,
                                 [&](Walk& walk, uint32_t i) { return walk.start(rays[i], hits[i]); });
}

// Occlusion of rays[ray_ids] in `tree`, kWalks walks interleaved.
template <class V, class Lanes, int kWalks>
void occluded_rays(const WideBvhView& tree, std::span<const uint32_t> ray_ids, const Ray* rays,
                   uint8_t* occluded) {
  using Walk = SteppedWalk<V, Lanes, true>;
  interleave_walks<kWalks, Walk>(tree, ray_ids,
                                 [&](Walk& walk, uint32_t i) { return walk.start(rays[i], occluded[i]); });
}

}  // namespace outcore::wide_kernels
