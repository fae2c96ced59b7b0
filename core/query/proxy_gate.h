// ProxyGate: the brick proxies' test before a ray is sent to a brick. A brick
// the ray's remaining segment cannot hit is passed over without being loaded
// or traced; proxies are conservative, so skipping never changes an answer.
//
// A proxy saves a load and a build, never tracing time (testing one costs
// about as much as tracing a small brick), so with reordering it is consulted
// only for bricks not known to be resident: a fully cached scene pays nothing
// for proxies. A stale view of what is resident costs at most a load or a test.
// When the budget holds the scene (nothing is evicted, so a brick is built at
// most once), the tests are deferred to the build: the queued strategy builds
// a brick only if one of its queued rays may hit it, testing them until the
// first that may, and otherwise passes them all over it (defer_to_builds()).
// A brick no ray can hit is still never built; a brick that is built costs
// one test or a few instead of one a ray.
//
// Before the proxy, the brick's bound (BrickBounds, --brick-bounds) when
// one beyond the upper hierarchy's boxes was chosen: it is cheap and tested
// whether the brick is resident or not, since its point is to spare brick
// visits that find nothing. admits() is the whole gate.
//
// Thread-safety: may_hit() and needs_no_test() run concurrently; the view of
// resident bricks is written only between parallel phases.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/proxy/proxy_set.h"
#include "core/query/visit_stats.h"
#include "core/ray/ray_types.h"
#include "core/upper/brick_bounds.h"

namespace outcore {

class ProxyGate {
 public:
  ProxyGate(const ProxySet* proxies, double hit_rounding, const BrickBounds* bounds = nullptr)
      : proxies_(proxies),
        hit_rounding_(hit_rounding),
        bounds_(bounds != nullptr && bounds->active() ? bounds : nullptr) {}

  const ProxySet* proxies() const { return proxies_; }

  // Starts keeping a view of the resident bricks (with reordering).
  void track_residency(uint32_t brick_count, const std::vector<uint32_t>& resident) {
    known_resident_.assign(brick_count, 0);
    mark_known_resident(resident);
  }
  bool tracks_residency() const { return !known_resident_.empty(); }
  // Rays are sent to bricks untested; the builder of a brick tests its queue.
  void defer_to_builds() { deferred_ = proxies_ != nullptr; }
  bool defers_to_builds() const { return deferred_; }
  // The view becomes exactly `resident`.
  void mark_known_resident(const std::vector<uint32_t>& resident) {
    std::fill(known_resident_.begin(), known_resident_.end(), uint8_t{0});
    for (const uint32_t b : resident) known_resident_[b] = 1;
  }
  void set_known_resident(uint32_t brick) {
    if (!known_resident_.empty()) known_resident_[brick] = 1;
  }

  // No test is wanted before sending a ray to `brick`: no proxies, tests
  // deferred to builds, or the brick is known to be resident.
  bool needs_no_test(uint32_t brick) const {
    return proxies_ == nullptr || deferred_ || (!known_resident_.empty() && known_resident_[brick]);
  }
  // Whether `ray` over [tnear, tmax] may hit `brick` (proxies present);
  // counts the test and its ticks.
  bool may_hit(uint32_t brick, const Ray& ray, float tmax, VisitCounters& counters) const {
    ++counters.proxy_tests;
    const uint64_t t0 = ticks();
    const bool may = proxies_->brick(brick).may_hit(ray, ray.tnear, tmax, hit_rounding_);
    counters.proxy_ticks += ticks() - t0;
    return may;
  }

  // Whether the bound (if one is tested) admits `ray` over [tnear, tmax] to
  // `brick`; counts a rejection in `counters`.
  bool bound_admits(uint32_t brick, const Ray& ray, float tmax, VisitCounters& counters) const {
    if (bound_may_hit(brick, ray, tmax)) return true;
    ++counters.skipped_by_bound;
    return false;
  }
  // The same, uncounted (trace-ahead counts when the visit is taken).
  bool bound_may_hit(uint32_t brick, const Ray& ray, float tmax) const {
    return bounds_ == nullptr || bounds_->may_hit(brick, ray, ray.tnear, tmax);
  }
  // The gate: the bound, then the proxy unless none is wanted; counts a
  // rejection by either (skipped_by_bound, skipped).
  bool admits(uint32_t brick, const Ray& ray, float tmax, VisitCounters& counters) const {
    if (!bound_admits(brick, ray, tmax, counters)) return false;
    if (needs_no_test(brick) || may_hit(brick, ray, tmax, counters)) return true;
    ++counters.skipped;
    return false;
  }

 private:
  const ProxySet* proxies_;
  double hit_rounding_;
  const BrickBounds* bounds_;            // null: only the upper hierarchy's boxes
  std::vector<uint8_t> known_resident_;  // empty: no view kept
  bool deferred_ = false;
};

}  // namespace outcore
