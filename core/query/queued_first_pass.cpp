#include "core/query/queued_first_pass.h"

#include <tbb/parallel_for.h>

#include <array>
#include <vector>

#include "core/query/brick_visit.h"
#include "core/query/ray_octants.h"
#include "core/upper/upper_packet_traversal.h"

namespace outcore {
namespace {

// The first-pass chunk's octants (ray_octants.h), indexed from its first ray.
using ChunkOctants = RayOctants<kRayGrain>;

// Rays i .. i+7 (`lanes` of them valid, sharing an octant: rays of
// neighbouring pixels; random rays rarely do) through the upper hierarchy
// together.
template <QueryKind kKind>
void first_windows_by_packet(StrategyContext<kKind>& ctx, std::size_t i, uint32_t lanes,
                             VisitCounters& counters) {
  constexpr uint32_t kLanes = SlabPacket::kLanes;
  const QueryBatch<kKind>& batch = ctx.batch;
  const RayWalk<kKind>& walk = ctx.walk;
  SlabPacket packet;
  for (uint32_t lane = 0; lane < kLanes; ++lane) {
    // Unused lanes get a copy of a used one: computed, never reported.
    const std::size_t from =
        (lanes >> lane & 1u) ? i + lane : i + static_cast<std::size_t>(__builtin_ctz(lanes));
    packet.set(lane, batch.rays[from], batch.rays[from].tnear, batch.horizon(from));
  }
  // Windows here, not in the rays' progress records: a ray that enters no
  // brick never has its record written.
  std::array<std::array<BrickKey, kWindow>, kLanes> windows;
  std::array<std::array<BrickKey, kWindow>*, kLanes> window_of;
  for (uint32_t lane = 0; lane < kLanes; ++lane) window_of[lane] = &windows[lane];
  uint32_t found[kLanes];
  first_bricks_wide_packet(walk.upper.wide, packet, lanes, window_of.data(), found, counters.nodes);
  RayProgress* const progress = ctx.scratch.progress.data();
  uint32_t* const first = ctx.scratch.first.data();
  for (uint32_t lane = 0; lane < kLanes; ++lane) {
    const std::size_t r = i + lane;
    first[r] = (lanes >> lane & 1u)
                   ? walk.start_with_window(progress[r], r, windows[lane], found[lane], counters)
                   : kInvalidId;
  }
}

// What the first pass over one chunk found.
struct FirstChunk {
  VisitCounters counters;
  std::size_t queued = 0;  // rays with a first brick
};

// Chunk c of the first pass.
template <QueryKind kKind>
FirstChunk first_bricks_of_chunk(StrategyContext<kKind>& ctx, std::size_t c, bool use_packet) {
  const QueryBatch<kKind>& batch = ctx.batch;
  RayProgress* const progress = ctx.scratch.progress.data();
  uint32_t* const first = ctx.scratch.first.data();
  FirstChunk chunk;
  VisitCounters& counters = chunk.counters;
  const std::size_t begin = c * kRayGrain, end = std::min(batch.size(), (c + 1) * kRayGrain);
  ChunkOctants octants;
  for (std::size_t i = begin; i < end; ++i) {
    // One pass over the chunk's rays: validity (unless checked apart), octant.
    bool valid;
    if (batch.validated_apart) {
      valid = batch.valid[i] != 0;
    } else {
      valid = batch.reset_and_check(i);
      batch.valid[i] = valid;
      counters.invalid_rays += !valid;
    }
    if (!use_packet) continue;
    if (valid) {
      octants.set(i - begin, batch.rays[i]);
    } else {
      octants.set_invalid(i - begin);
    }
  }
  for (std::size_t i = begin; i < end;) {
    if (use_packet && i + SlabPacket::kLanes <= end) {
      const uint32_t lanes = octants.packet_lanes(i - begin);
      if (lanes != 0) {
        first_windows_by_packet(ctx, i, lanes, counters);
        i += SlabPacket::kLanes;
        continue;
      }
    }
    first[i] = batch.valid[i] ? ctx.walk.start(progress[i], i, counters) : kInvalidId;
    ++i;
  }
  for (std::size_t i = begin; i < end; ++i) chunk.queued += first[i] != kInvalidId;
  return chunk;
}

}  // namespace

template <QueryKind kKind>
void queue_first_bricks(StrategyContext<kKind>& ctx, BrickQueues& queues) {
  const auto t_upper = Clock::now();
  const std::size_t n = ctx.batch.size();
  const bool use_packet = !ctx.walk.upper.use_flat && ctx.walk.use_avx;
  if (ctx.scratch.first.size() < n) ctx.scratch.first.resize(n);
  const std::size_t chunks = (n + kRayGrain - 1) / kRayGrain;
  std::vector<FirstChunk> chunk_results(chunks);
  tbb::parallel_for(std::size_t{0}, chunks,
                    [&](std::size_t c) { chunk_results[c] = first_bricks_of_chunk(ctx, c, use_packet); });
  const std::vector<uint32_t>& first = ctx.scratch.first;
  for (std::size_t c = 0; c < chunks; ++c) {
    ctx.tally.add(chunk_results[c].counters);
    // A chunk in which no ray enters a brick costs nothing here.
    if (chunk_results[c].queued == 0) continue;
    const std::size_t end = std::min(n, (c + 1) * kRayGrain);
    for (std::size_t i = c * kRayGrain; i < end; ++i) {
      if (first[i] != kInvalidId) queues.enqueue(first[i], static_cast<uint32_t>(i));
    }
  }
  ctx.tally.stats.seconds_upper = seconds_since(t_upper);
}

template void queue_first_bricks(StrategyContext<QueryKind::kClosestHit>&, BrickQueues&);
template void queue_first_bricks(StrategyContext<QueryKind::kAnyHit>&, BrickQueues&);
template void queue_first_bricks(StrategyContext<QueryKind::kAllHits>&, BrickQueues&);

}  // namespace outcore
