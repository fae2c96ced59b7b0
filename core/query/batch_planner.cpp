#include "core/query/batch_planner.h"

namespace outcore {
namespace {

// Why a batch whose bricks are all resident under a budget that holds the
// scene is not traced through a resident set.
std::string_view why_no_set(const QueryOptions& options, const BatchFacts& facts) {
  if (!options.brick_set) return "every brick resident, few bricks; the resident set is off";
  if (!options.only_bricks.empty())
    return "every brick resident, few bricks; the batch traces a part of them";
  if (facts.resident_set_max_bricks == 0)
    return "every brick resident, few bricks; the brick structure offers no resident set";
  if (facts.brick_count == 0) return "every brick resident, few bricks; the scene has no bricks";
  if (facts.brick_count > facts.resident_set_max_bricks)
    return "every brick resident, few bricks; more than the structure's resident set serves";
  return "every brick resident, few bricks; the batch is below brick_set_min_rays";
}

// Why a reordered batch is not traced in chunks.
std::string_view why_queued(const QueryOptions& options, const BatchFacts& facts) {
  if (!facts.cache_fits_scene) return "the budget cannot hold the scene";
  if (facts.resident_bricks != facts.brick_count) return "not every brick is resident";
  if (facts.brick_count > kChunkedMaxBricks) return "too many bricks for the chunked strategies";
  if (!options.in_cache_sweep) return "every brick resident, few bricks; the in-cache sweep is off";
  return "queued";
}

}  // namespace

BatchPlan plan_batch(const QueryOptions& options, const BatchFacts& facts) {
  if (!options.reorder) return {BatchStrategy::kSequential, "reordering is off"};
  // Nothing can be evicted and nothing needs loading: queueing the batch at
  // bricks buys no reuse.
  const bool all_resident = facts.cache_fits_scene && facts.resident_bricks == facts.brick_count;
  const bool few_bricks = facts.brick_count <= kChunkedMaxBricks;
  if (all_resident && options.brick_set && options.only_bricks.empty() &&
      facts.brick_count <= facts.resident_set_max_bricks && facts.brick_count > 0 &&
      facts.rays >= options.brick_set_min_rays) {
    return {BatchStrategy::kResidentSet,
            "every brick resident, a resident set offered for them, a large batch"};
  }
  if (all_resident && few_bricks && options.in_cache_sweep)
    return {BatchStrategy::kInCacheSweep, why_no_set(options, facts)};
  return {BatchStrategy::kQueued, why_queued(options, facts)};
}

std::string_view strategy_name(BatchStrategy strategy) {
  switch (strategy) {
    case BatchStrategy::kSequential: return "sequential";
    case BatchStrategy::kResidentSet: return "resident set";
    case BatchStrategy::kInCacheSweep: return "in-cache sweep";
    case BatchStrategy::kQueued: return "queued";
  }
  return "?";
}

}  // namespace outcore
