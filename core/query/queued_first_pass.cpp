#include "core/query/queued_first_pass.h"

#include <tbb/parallel_for.h>

#include <array>
#include <cmath>
#include <vector>

#include "core/query/brick_visit.h"
#include "core/upper/upper_packet_traversal.h"
#include "core/util/cpu_features.h"

namespace outcore {
namespace {

// Rays i .. i+7 through the upper hierarchy together when their directions
// share an octant (rays of neighbouring pixels; random rays rarely do);
// false, with nothing done, when they do not.
template <QueryKind kKind>
bool first_windows_by_packet(StrategyContext<kKind>& ctx, std::size_t i, VisitCounters& counters) {
  constexpr uint32_t kLanes = SlabPacket::kLanes;
  const QueryBatch<kKind>& batch = ctx.batch;
  const RayWalk<kKind>& walk = ctx.walk;
  RayProgress* const progress = ctx.scratch.progress.data();
  uint32_t lanes = 0;
  int octant = -1;
  for (uint32_t lane = 0; lane < kLanes; ++lane) {
    if (!batch.valid[i + lane]) continue;
    const Vec3f& d = batch.rays[i + lane].direction;
    const int o = int(std::signbit(d.x)) | int(std::signbit(d.y)) << 1 | int(std::signbit(d.z)) << 2;
    if (octant >= 0 && o != octant) return false;
    octant = o;
    lanes |= 1u << lane;
  }
  if (__builtin_popcount(lanes) < 2) return false;
  SlabPacket packet;
  std::array<std::array<BrickKey, kWindow>*, kLanes> windows;
  for (uint32_t lane = 0; lane < kLanes; ++lane) {
    const std::size_t r = i + lane;
    progress[r] = RayProgress{};
    windows[lane] = &progress[r].window;
    // Unused lanes get a copy of a used one: computed, never reported.
    const std::size_t from = (lanes >> lane & 1u) ? r : i + static_cast<std::size_t>(__builtin_ctz(lanes));
    packet.set(lane, batch.rays[from], batch.rays[from].tnear, batch.horizon(from));
  }
  uint32_t found[kLanes];
  first_bricks_wide_packet(walk.upper.wide, packet, lanes, windows.data(), found, counters.nodes);
  uint32_t* const first = ctx.scratch.first.data();
  for (uint32_t lane = 0; lane < kLanes; ++lane) {
    const std::size_t r = i + lane;
    if (!(lanes >> lane & 1u)) {
      first[r] = kInvalidId;
      continue;
    }
    walk.begin_window(progress[r], r, found[lane]);
    first[r] = walk.advance(progress[r], r, counters);
  }
  return true;
}

// Chunk c of the first pass.
template <QueryKind kKind>
VisitCounters first_bricks_of_chunk(StrategyContext<kKind>& ctx, std::size_t c, bool use_packet) {
  const QueryBatch<kKind>& batch = ctx.batch;
  RayProgress* const progress = ctx.scratch.progress.data();
  uint32_t* const first = ctx.scratch.first.data();
  VisitCounters counters;
  const std::size_t end = std::min(batch.size(), (c + 1) * kRayGrain);
  if (!batch.validated_apart) {
    for (std::size_t i = c * kRayGrain; i < end; ++i) {
      batch.valid[i] = batch.reset_and_check(i);
      counters.invalid_rays += !batch.valid[i];
    }
  }
  for (std::size_t i = c * kRayGrain; i < end;) {
    if (use_packet && i + SlabPacket::kLanes <= end && first_windows_by_packet(ctx, i, counters)) {
      i += SlabPacket::kLanes;
      continue;
    }
    // Reset here, not in the validation pass: one pass over this memory.
    progress[i] = RayProgress{};
    first[i] = batch.valid[i] ? ctx.walk.advance(progress[i], i, counters) : kInvalidId;
    ++i;
  }
  return counters;
}

}  // namespace

template <QueryKind kKind>
void queue_first_bricks(StrategyContext<kKind>& ctx, BrickQueues& queues) {
  const auto t_upper = Clock::now();
  const std::size_t n = ctx.batch.size();
  const bool use_packet = !ctx.walk.upper.use_flat && ctx.walk.use_avx;
  if (ctx.scratch.first.size() < n) ctx.scratch.first.resize(n);
  const std::size_t chunks = (n + kRayGrain - 1) / kRayGrain;
  std::vector<VisitCounters> chunk_counters(chunks);
  tbb::parallel_for(std::size_t{0}, chunks,
                    [&](std::size_t c) { chunk_counters[c] = first_bricks_of_chunk(ctx, c, use_packet); });
  for (const VisitCounters& counters : chunk_counters) ctx.tally.add(counters);
  const std::vector<uint32_t>& first = ctx.scratch.first;
  for (std::size_t i = 0; i < n; ++i) {
    if (first[i] != kInvalidId) queues.enqueue(first[i], static_cast<uint32_t>(i));
  }
  ctx.tally.stats.seconds_upper = seconds_since(t_upper);
}

template void queue_first_bricks(StrategyContext<QueryKind::kClosestHit>&, BrickQueues&);
template void queue_first_bricks(StrategyContext<QueryKind::kAnyHit>&, BrickQueues&);

}  // namespace outcore
