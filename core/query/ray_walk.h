// RayWalk: one ray's front-to-back walk over the bricks the upper hierarchy
// finds for it. A ray keeps a small window of upcoming bricks (refilled by
// re-traversal from its last brick when used up) and advances brick by
// brick, finishing once its hit is nearer than the next brick's entry
// (closest hit) or at its first hit (any hit). Each ray therefore visits the
// same bricks in the same order whatever the strategy, batch, budget or
// thread count, so answers are bitwise identical across all of them.
//
// A walk begins with start(): a ray whose first upper walk finds no brick
// (its segment misses the scene's box, or passes between the bricks' boxes)
// is answered there, a miss, without its progress record being written, a
// queue entry or any per-brick bookkeeping: on a sparse scene most rays hit
// nothing, and they cost their validation and one short walk. No separate
// test against the scene's box comes first: the walk's first node is that
// test (its children's boxes cover the scene's box and are tested in one
// SIMD operation), and a separate one, measured on the sparse benchmark
// scene, saved about 5 ns of CPU per ray that misses the box but added about
// 10 ns per ray that enters it.
//
// A brick the ray cannot hit by its bound or its proxy (ProxyGate) is passed
// over like a traced brick without a hit; one the ray was traced against ahead of its
// turn (trace_ahead.h) is passed over too, its hit (if any) taken now: the
// visit happens, only earlier.
//
// Thread-safety: start() and advance() run concurrently on distinct rays.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/query/brick_demand.h"
#include "core/query/proxy_gate.h"
#include "core/query/query_batch.h"
#include "core/query/upper_walks.h"
#include "core/query/visit_stats.h"

namespace outcore {

// Upcoming bricks kept per ray; more are found by re-traversal when used up.
constexpr std::size_t kWindow = 4;

// What is known of a window entry the ray has not reached yet: nothing, or
// the outcome of tracing it there ahead of its turn; values from
// kAheadHitBase on index the batch's table of such hits (closest hit), or
// kAheadHitBase says the ray was found occluded there (any hit).
constexpr uint32_t kAheadNone = 0;
constexpr uint32_t kAheadSkip = 1;       // its proxy says the ray cannot hit it
constexpr uint32_t kAheadBoundSkip = 2;  // its bound (--brick-bounds) says so
constexpr uint32_t kAheadNoGain = 3;     // traced: nothing beats what the ray had then
constexpr uint32_t kAheadHitBase = 4;

struct RayProgress {
  std::array<BrickKey, kWindow> window;
  BrickKey last;  // the key of the brick being (or last) traced
  uint8_t count = 0;
  uint8_t next = 0;
  // The last fill found fewer than kWindow bricks: the window holds every
  // brick left (horizons only shrink), so no refill is needed.
  bool complete = false;
  // Window entries already listed at their brick for trace-ahead (bit k).
  uint8_t listed = 0;
};

template <QueryKind kKind>
struct RayWalk {
  const QueryBatch<kKind>& batch;
  const UpperWalks& upper;
  bool use_avx;
  const ProxyGate& gate;
  BrickDemand& demand;
  // kAhead* per ray and window entry; null when trace-ahead is impossible
  // (the budget holds the scene, or it is off).
  std::array<uint32_t, kWindow>* ahead_state;
  const std::vector<Hit>& ahead_hits;  // the hits found ahead, by kAheadHitBase + k

  // Ray i's window was just filled with `found` keys: nothing of it used yet.
  void begin_window(RayProgress& p, std::size_t i, uint32_t found) const {
    p.count = static_cast<uint8_t>(found);
    p.complete = p.count < kWindow;
    p.next = 0;
    if (ahead_state != nullptr) ahead_state[i] = {};
    p.listed = 0;
    if (demand.tracking()) {
      for (uint8_t k = 0; k < p.count; ++k) demand.add(p.window[k].brick);
    }
  }

  // The rest of the window is not needed: its demand goes (entries traced
  // ahead already gave theirs back).
  void drop_window(RayProgress& p, std::size_t i) const {
    if (!demand.tracking()) return;
    for (; p.next < p.count; ++p.next) {
      if (ahead_state == nullptr || ahead_state[i][p.next] == kAheadNone) demand.sub(p.window[p.next].brick);
    }
  }

  // Begins ray i's walk (its answer reset, the ray valid): returns the first
  // brick to trace it at, its progress `p` set up, or kInvalidId when the
  // ray enters no brick, `p` then untouched. The same bricks, in the same
  // order, as advance() from a fresh record.
  uint32_t start(RayProgress& p, std::size_t i, VisitCounters& counters) const {
    const Ray& ray = batch.rays[i];
    const SlabRay slab_ray(ray);
    const float limit = batch.horizon(i);
    std::array<BrickKey, kWindow> window;
    const uint32_t found =
        upper.next_window(use_avx, slab_ray, ray.tnear, limit, BrickKey{}, window, counters.nodes);
    return start_with_window(p, i, window, found, counters);
  }

  // start() for a ray whose first window (`found` keys after BrickKey{},
  // over its whole segment) was found by other means (a packet walk).
  uint32_t start_with_window(RayProgress& p, std::size_t i, const std::array<BrickKey, kWindow>& window,
                             uint32_t found, VisitCounters& counters) const {
    if (found == 0) {
      ++counters.no_brick;
      return kInvalidId;
    }
    p = RayProgress{};
    p.window = window;
    begin_window(p, i, found);
    const BrickKey& key = p.window[0];
    p.last = key;
    p.next = 1;
    if (gate.admits(key.brick, batch.rays[i], batch.horizon(i), counters)) return key.brick;
    if (demand.tracking()) demand.sub(key.brick);
    return advance(p, i, counters);
  }

  // Moves ray i (progress `p`) past its current brick; returns the next
  // brick to trace it at, or kInvalidId when it is done.
  uint32_t advance(RayProgress& p, std::size_t i, VisitCounters& counters) const {
    float limit = batch.horizon(i);
    for (;;) {
      if (batch.finished(i)) {
        drop_window(p, i);
        return kInvalidId;
      }
      BrickKey key;
      uint32_t ahead = kAheadNone;
      if (p.next < p.count) {
        key = p.window[p.next];
        if (key.entry > limit) {
          drop_window(p, i);
          return kInvalidId;
        }
        if (ahead_state != nullptr) ahead = ahead_state[i][p.next];
        p.last = key;
        ++p.next;
      } else {
        if (p.complete) return kInvalidId;
        const Ray& ray = batch.rays[i];
        const SlabRay slab_ray(ray);
        begin_window(
            p, i, upper.next_window(use_avx, slab_ray, ray.tnear, limit, p.last, p.window, counters.nodes));
        if (p.count == 0) return kInvalidId;
        key = p.window[0];
        p.last = key;
        p.next = 1;
      }
      if (ahead != kAheadNone) {
        take_ahead(ahead, i, limit, counters);
        continue;
      }
      if (gate.admits(key.brick, batch.rays[i], limit, counters)) return key.brick;
      // Passed over: the ray no longer needs the brick.
      if (demand.tracking()) demand.sub(key.brick);
    }
  }

 private:
  // The visit to a brick traced ahead: its outcome is taken now.
  void take_ahead(uint32_t ahead, std::size_t i, float& limit, VisitCounters& counters) const {
    if (ahead == kAheadSkip || ahead == kAheadBoundSkip) {
      ++(ahead == kAheadSkip ? counters.skipped : counters.skipped_by_bound);
      return;
    }
    ++counters.ahead_visits;
    bool gained = ahead >= kAheadHitBase;
    if constexpr (kKind == QueryKind::kClosestHit) {
      if (gained) {
        const Hit& found = ahead_hits[ahead - kAheadHitBase];
        Hit& hit = batch.hits[i];
        gained = hit_is_better(found.t, found.geometry_id, found.primitive_id, hit);
        if (gained) hit = found;
        limit = batch.horizon(i);
      }
    }
    counters.visits_without_hit += !gained;
  }
};

}  // namespace outcore
