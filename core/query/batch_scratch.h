// BatchScratch: a batch's working memory (per-ray progress, brick queues,
// trace-ahead tables, the in-cache sweep's per-thread state), kept in the
// engine's ReusePool for the next batch so that warm batches neither
// allocate nor page-fault it. Vectors only grow (new elements are
// value-initialised once) and every element a batch reads is overwritten by
// it first; the brick queues keep their capacity (a traced queue swaps
// buffers with the wave's batch instead of freeing it).
//
// Thread-safety: one batch at a time (a lease).
#pragma once

#include <tbb/enumerable_thread_specific.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/query/ray_walk.h"

namespace outcore {

// Rays per task of the chunked strategies (in-cache sweep, resident set):
// the sweep's per-ray state (about 60 bytes a ray) and the rays' own records
// stay in a core's L2 cache.
constexpr std::size_t kSweepRays = 1024;

// One thread's working memory for the in-cache sweep of one chunk of rays.
struct SweepScratch {
  std::array<RayProgress, kSweepRays> progress;
  std::array<uint32_t, kSweepRays> at;       // the brick each active ray is at
  std::array<uint32_t, kSweepRays> active;   // chunk-local indices of the rays with a brick to trace
  std::array<uint32_t, kSweepRays> grouped;  // the active rays' ids, grouped by brick
  std::vector<uint32_t> group_end;           // per brick; all zero between rounds
  std::vector<uint32_t> touched;             // bricks with active rays, in first-seen order
};

struct BatchScratch {
  std::vector<uint8_t> valid;
  std::vector<RayProgress> progress;
  std::vector<uint32_t> first;
  std::vector<std::vector<uint32_t>> queues;
  std::vector<std::vector<uint32_t>> wave_batches;
  // Trace-ahead: per brick, rays with it further on in their window; and the
  // hits found ahead of their turn.
  std::vector<std::vector<uint32_t>> upcoming;
  // kAhead* per ray and window entry (apart from RayProgress, which stays
  // small for batches that fit the cache).
  std::vector<std::array<uint32_t, kWindow>> ahead_state;
  std::vector<Hit> ahead_hits;
  std::vector<Ray> ahead_ray_copies;
  std::vector<Hit> ahead_hit_copies;
  std::vector<uint8_t> ahead_occluded;
  std::vector<uint32_t> ahead_outcomes;
  tbb::enumerable_thread_specific<SweepScratch> sweep;
};

// Batches up to this many rays give their scratch back for reuse (about 50
// bytes per ray); larger ones free it, so one huge batch does not pin its
// memory for good.
constexpr std::size_t kKeptScratchRays = std::size_t{1} << 21;
// Scratches kept for reuse (one per concurrent batch).
constexpr std::size_t kKeptScratches = 2;

inline bool keep_batch_scratch(const BatchScratch& scratch) {
  return scratch.progress.size() <= kKeptScratchRays;
}

}  // namespace outcore
