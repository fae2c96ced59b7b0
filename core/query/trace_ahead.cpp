#include "core/query/trace_ahead.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>

#include "core/query/brick_visit.h"

namespace outcore {

template <QueryKind kKind>
void TraceAhead<kKind>::select(uint32_t brick, std::span<const uint32_t> busy) {
  const QueryBatch<kKind>& batch = walk_.batch;
  std::vector<uint32_t>& listed = queues_.upcoming(brick);
  for (const uint32_t ray : listed) {
    const RayProgress& p = scratch_.progress[ray];
    if (batch.finished(ray)) continue;
    if (std::find(busy.begin(), busy.end(), p.last.brick) != busy.end()) continue;
    for (uint8_t k = p.next; k < p.count; ++k) {
      if (p.window[k].brick != brick) continue;
      uint32_t& state = walk_.ahead_state[ray][k];
      if (state == kAheadNone && p.window[k].entry <= batch.horizon(ray)) {
        state = kAheadNoGain;
        rays_.push_back(ray);
        slots_.push_back(k);
      }
      break;
    }
  }
  listed.clear();
}

template <QueryKind kKind>
void TraceAhead<kKind>::reserve(std::size_t m) {
  if (scratch_.ahead_ray_copies.size() < m) scratch_.ahead_ray_copies.resize(m);
  if (scratch_.ahead_outcomes.size() < m) scratch_.ahead_outcomes.resize(m);
  if constexpr (kKind == QueryKind::kClosestHit) {
    if (scratch_.ahead_hit_copies.size() < m) scratch_.ahead_hit_copies.resize(m);
  } else {
    if (scratch_.ahead_occluded.size() < m) scratch_.ahead_occluded.resize(m);
  }
}

template <QueryKind kKind>
void TraceAhead<kKind>::trace_range(uint32_t brick, const BrickAccel& accel, std::size_t begin,
                                    std::size_t end, VisitCounters& counters) {
  const QueryBatch<kKind>& batch = walk_.batch;
  const ProxyGate& gate = walk_.gate;
  Ray* const ray_copies = scratch_.ahead_ray_copies.data();
  Hit* const hit_copies = scratch_.ahead_hit_copies.data();
  uint8_t* const occluded_copies = scratch_.ahead_occluded.data();
  uint32_t* const outcomes = scratch_.ahead_outcomes.data();
  for (std::size_t from = begin; from < end; from += kRayGrain) {
    uint32_t ids[kRayGrain];
    std::size_t traced = 0;
    for (std::size_t j = from; j < std::min(end, from + kRayGrain); ++j) {
      const uint32_t ray = rays_[j];
      const Ray& r = batch.rays[ray];
      if (!gate.bound_may_hit(brick, r, batch.horizon(ray))) {
        outcomes[j] = kAheadBoundSkip;
        continue;
      }
      if (gate.proxies() != nullptr && !gate.may_hit(brick, r, batch.horizon(ray), counters)) {
        outcomes[j] = kAheadSkip;
        continue;
      }
      outcomes[j] = kAheadNoGain;
      ray_copies[j] = batch.rays[ray];
      if constexpr (kKind == QueryKind::kClosestHit) {
        hit_copies[j] = batch.hits[ray];
      } else {
        occluded_copies[j] = 0;
      }
      ids[traced++] = static_cast<uint32_t>(j);
    }
    const std::span<const uint32_t> traced_ids(ids, traced);
    if constexpr (kKind == QueryKind::kClosestHit) {
      accel.intersect(traced_ids, ray_copies, hit_copies);
      for (const uint32_t j : traced_ids) {
        const Hit& found = hit_copies[j];
        if (hit_is_better(found.t, found.geometry_id, found.primitive_id, batch.hits[rays_[j]]))
          outcomes[j] = kAheadHitBase;
      }
    } else {
      accel.occluded(traced_ids, ray_copies, occluded_copies);
      for (const uint32_t j : traced_ids) {
        if (occluded_copies[j] != 0) outcomes[j] = kAheadHitBase;
      }
    }
    counters.ahead_traces += traced;
  }
}

template <QueryKind kKind>
void TraceAhead<kKind>::file(BatchTally& tally) {
  const uint32_t* const outcomes = scratch_.ahead_outcomes.data();
  for (std::size_t j = 0; j < rays_.size(); ++j) {
    const uint32_t ray = rays_[j];
    uint32_t outcome = outcomes[j];
    if (outcome == kAheadHitBase) {
      if constexpr (kKind == QueryKind::kClosestHit) {
        outcome = kAheadHitBase + static_cast<uint32_t>(scratch_.ahead_hits.size());
        scratch_.ahead_hits.push_back(scratch_.ahead_hit_copies[j]);
      } else {
        // The ray is occluded now; the visit, taken later, counts the hit.
        walk_.batch.occluded[ray] = 1;
      }
    }
    const RayProgress& p = scratch_.progress[ray];
    if (walk_.demand.tracking()) walk_.demand.sub(p.window[slots_[j]].brick);
    walk_.ahead_state[ray][slots_[j]] = outcome;
  }
  for (const VisitCounters& counters : counters_) tally.add(counters);
  rays_.clear();
  slots_.clear();
}

template <QueryKind kKind>
void TraceAhead<kKind>::trace_at(uint32_t brick, const BrickAccel& accel, BatchTally& tally) {
  select(brick, {});
  const std::size_t m = rays_.size();
  reserve(m);
  const std::size_t chunks = (m + kRayGrain - 1) / kRayGrain;
  counters_.assign(chunks, VisitCounters{});
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      trace_range(brick, accel, c * kRayGrain, std::min(m, (c + 1) * kRayGrain), counters_[c]);
    });
  });
  file(tally);
}

template class TraceAhead<QueryKind::kClosestHit>;
template class TraceAhead<QueryKind::kAnyHit>;
template class TraceAhead<QueryKind::kAllHits>;

}  // namespace outcore
