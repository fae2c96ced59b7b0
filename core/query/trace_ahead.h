// Trace-ahead, for the queued strategy under a budget that cannot hold the
// scene: a brick built for its queue may be evicted before the rays that
// reach it later (those with it further on in their window) get there, and
// be built again. So when a build may evict, the rays with the brick further
// on are traced against it too, while it is pinned, and the outcome is kept
// for when they get there (RayWalk reads it). A closest hit found ahead is
// taken only when the ray reaches the brick, by hit_is_better(), which is
// what tracing it then would give (the brick's best hit does not depend on
// how far the ray was clipped when it was traced), so answers stay bitwise
// the same; an any-hit found ahead finishes the ray at once (occlusion is an
// OR over bricks).
//
// Thread-safety: select() and file() run on one thread between parallel
// phases; trace_range() runs concurrently on disjoint candidate ranges.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/query/batch_scratch.h"
#include "core/query/brick_queues.h"
#include "core/query/ray_walk.h"
#include "core/query/visit_stats.h"

namespace outcore {

template <QueryKind kKind>
class TraceAhead {
 public:
  TraceAhead(const RayWalk<kKind>& walk, BatchScratch& scratch, BrickQueues& queues)
      : walk_(walk), scratch_(scratch), queues_(queues) {}

  // Appends the rays listed at `brick` that have not reached it yet (one per
  // (ray, entry) however often it was listed; not those beyond their
  // horizon, which will never reach it) and marks their entries taken. Rays
  // whose current brick is in `busy` are left out: they are being traced
  // there at the same time.
  void select(uint32_t brick, std::span<const uint32_t> busy);
  // Candidates selected so far (not yet filed).
  std::size_t selected() const { return rays_.size(); }
  // Room for m candidates' copies and outcomes.
  void reserve(std::size_t m);
  // Traces candidates [begin, end) against `brick` on copies of their rays
  // and hits (the rays themselves are not at the brick yet); writes only
  // those copies and the outcomes.
  void trace_range(uint32_t brick, const BrickAccel& accel, std::size_t begin, std::size_t end,
                   VisitCounters& counters);
  // Per-task counters for trace_range(), summed by file().
  std::vector<VisitCounters>& task_counters() { return counters_; }
  // Files the outcomes in the rays' windows (serially: hits found ahead go to
  // one table) and sums the task counters. An occlusion found ahead finishes
  // its ray now.
  void file(BatchTally& tally);
  // Trace-ahead at one pinned brick, in parallel chunks.
  void trace_at(uint32_t brick, const BrickAccel& accel, BatchTally& tally);

 private:
  const RayWalk<kKind>& walk_;
  BatchScratch& scratch_;
  BrickQueues& queues_;
  std::vector<uint32_t> rays_;  // candidates of the bricks being built (concatenated)
  std::vector<uint8_t> slots_;  // their window entries
  std::vector<VisitCounters> counters_;
};

}  // namespace outcore
