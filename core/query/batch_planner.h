// The batch planner: which strategy answers a batch, and why. One function,
// plan_batch(), over the query's options and what is known of the engine
// when the batch starts; the strategies are in strategy_*.cpp.
//
//   sequential      reordering off: rays one by one in input order.
//   resident set    every brick resident under a budget that holds the
//                   scene, the brick structure offers a ResidentBrickSet
//                   for that many bricks, the set is on, and the batch has
//                   at least brick_set_min_rays rays (the set is made per
//                   batch).
//   in-cache sweep  every brick resident under a budget that holds the
//                   scene, at most kChunkedMaxBricks bricks, the sweep on.
//   queued          otherwise: rays queue at bricks, brick by brick.
//
// All four give bitwise the same answers; only speed and statistics differ.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/query/query_engine.h"

namespace outcore {

enum class BatchStrategy { kSequential, kResidentSet, kInCacheSweep, kQueued };

// The chunked strategies (set and sweep) serve scenes of at most this many
// bricks: with many, a chunk's rays spread over so many bricks that each
// visit starts cold in a brick's structure, and queueing the whole batch at
// each brick is faster (docs/BENCHMARKS.md).
constexpr uint32_t kChunkedMaxBricks = 16;

// What is known of the engine when the batch starts.
struct BatchFacts {
  std::size_t rays = 0;
  uint32_t brick_count = 0;
  uint32_t resident_bricks = 0;
  bool cache_fits_scene = false;         // the budget holds every brick at once
  uint32_t resident_set_max_bricks = 0;  // the builder's (0: it offers no set)
};

struct BatchPlan {
  BatchStrategy strategy;
  std::string_view reason;  // a short line: why this strategy (static text)
};

BatchPlan plan_batch(const QueryOptions& options, const BatchFacts& facts);

// "sequential", "resident set", "in-cache sweep", "queued".
std::string_view strategy_name(BatchStrategy strategy);

}  // namespace outcore
