// ProxyGate: the brick proxies' test before a ray is sent to a brick. A brick
// the ray's remaining segment cannot hit is passed over without being loaded
// or traced; proxies are conservative, so skipping never changes an answer.
//
// A proxy saves a load and a build, never tracing time (testing one costs
// about as much as tracing a small brick), so with reordering it is consulted
// only for bricks not known to be resident: a fully cached scene pays nothing
// for proxies. A stale view of what is resident costs at most a load or a test.
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

namespace outcore {

class ProxyGate {
 public:
  ProxyGate(const ProxySet* proxies, double hit_rounding) : proxies_(proxies), hit_rounding_(hit_rounding) {}

  const ProxySet* proxies() const { return proxies_; }

  // Starts keeping a view of the resident bricks (with reordering).
  void track_residency(uint32_t brick_count, const std::vector<uint32_t>& resident) {
    known_resident_.assign(brick_count, 0);
    mark_known_resident(resident);
  }
  bool tracks_residency() const { return !known_resident_.empty(); }
  // The view becomes exactly `resident`.
  void mark_known_resident(const std::vector<uint32_t>& resident) {
    std::fill(known_resident_.begin(), known_resident_.end(), uint8_t{0});
    for (const uint32_t b : resident) known_resident_[b] = 1;
  }
  void set_known_resident(uint32_t brick) {
    if (!known_resident_.empty()) known_resident_[brick] = 1;
  }

  // No test is wanted before sending a ray to `brick`: no proxies, or the
  // brick is known to be resident.
  bool needs_no_test(uint32_t brick) const {
    return proxies_ == nullptr || (!known_resident_.empty() && known_resident_[brick]);
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

 private:
  const ProxySet* proxies_;
  double hit_rounding_;
  std::vector<uint8_t> known_resident_;  // empty: no view kept
};

}  // namespace outcore
