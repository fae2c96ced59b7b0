#include "core/query/batch_planner.h"

#include <gtest/gtest.h>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// A batch over a scene of 3 bricks, all resident under a budget that holds
// them, with a structure that offers a resident set: every fast path open.
BatchFacts open_facts() {
  BatchFacts facts;
  facts.rays = 1 << 20;
  facts.brick_count = 3;
  facts.resident_bricks = 3;
  facts.cache_fits_scene = true;
  facts.resident_set_max_bricks = kChunkedMaxBricks;
  return facts;
}

TEST(BatchPlanner, ReorderingOffIsSequentialWhateverElseHolds) {
  QueryOptions options;
  options.reorder = false;
  const BatchPlan plan = plan_batch(options, open_facts());
  EXPECT_EQ(plan.strategy, BatchStrategy::kSequential);
  EXPECT_EQ(plan.reason, "reordering is off");
  BatchFacts cold = open_facts();
  cold.resident_bricks = 0;
  cold.cache_fits_scene = false;
  EXPECT_EQ(plan_batch(options, cold).strategy, BatchStrategy::kSequential);
}

TEST(BatchPlanner, AResidentSceneOfFewBricksAndALargeBatchTakeTheResidentSet) {
  const BatchPlan plan = plan_batch(QueryOptions{}, open_facts());
  EXPECT_EQ(plan.strategy, BatchStrategy::kResidentSet);
  EXPECT_NE(plan.reason.find("resident set offered"), std::string_view::npos) << plan.reason;
  // Exactly brick_set_min_rays rays and exactly kChunkedMaxBricks bricks still do.
  BatchFacts edge = open_facts();
  edge.rays = QueryOptions{}.brick_set_min_rays;
  edge.brick_count = edge.resident_bricks = kChunkedMaxBricks;
  EXPECT_EQ(plan_batch(QueryOptions{}, edge).strategy, BatchStrategy::kResidentSet);
}

TEST(BatchPlanner, ASetOfferedForAnyNumberOfBricksServesAResidentSceneOfMany) {
  BatchFacts many = open_facts();
  many.brick_count = many.resident_bricks = 5000;
  many.resident_set_max_bricks = 5000;
  EXPECT_EQ(plan_batch(QueryOptions{}, many).strategy, BatchStrategy::kResidentSet);
  // One brick beyond what the structure offers: queued (too many to sweep).
  many.resident_set_max_bricks = 4999;
  const BatchPlan plan = plan_batch(QueryOptions{}, many);
  EXPECT_EQ(plan.strategy, BatchStrategy::kQueued);
  EXPECT_EQ(plan.reason, "too many bricks for the chunked strategies");
}

TEST(BatchPlanner, WithoutTheSetAResidentSceneOfFewBricksIsSwept) {
  QueryOptions off;
  off.brick_set = false;
  BatchPlan plan = plan_batch(off, open_facts());
  EXPECT_EQ(plan.strategy, BatchStrategy::kInCacheSweep);
  EXPECT_NE(plan.reason.find("resident set is off"), std::string_view::npos) << plan.reason;

  BatchFacts no_offer = open_facts();
  no_offer.resident_set_max_bricks = 0;
  plan = plan_batch(QueryOptions{}, no_offer);
  EXPECT_EQ(plan.strategy, BatchStrategy::kInCacheSweep);
  EXPECT_NE(plan.reason.find("offers no resident set"), std::string_view::npos) << plan.reason;

  BatchFacts beyond = open_facts();
  beyond.resident_set_max_bricks = beyond.brick_count - 1;
  plan = plan_batch(QueryOptions{}, beyond);
  EXPECT_EQ(plan.strategy, BatchStrategy::kInCacheSweep);
  EXPECT_NE(plan.reason.find("more than the structure's resident set serves"), std::string_view::npos)
      << plan.reason;

  BatchFacts small = open_facts();
  small.rays = QueryOptions{}.brick_set_min_rays - 1;
  plan = plan_batch(QueryOptions{}, small);
  EXPECT_EQ(plan.strategy, BatchStrategy::kInCacheSweep);
  EXPECT_NE(plan.reason.find("brick_set_min_rays"), std::string_view::npos) << plan.reason;

  BatchFacts empty = open_facts();
  empty.brick_count = empty.resident_bricks = 0;
  plan = plan_batch(QueryOptions{}, empty);
  EXPECT_EQ(plan.strategy, BatchStrategy::kInCacheSweep);
  EXPECT_NE(plan.reason.find("no bricks"), std::string_view::npos) << plan.reason;
}

TEST(BatchPlanner, EverythingElseIsQueuedAndSaysWhy) {
  struct Case {
    const char* name;
    BatchFacts facts;
    QueryOptions options;
    std::string_view reason;
  };
  BatchFacts over_budget = open_facts();
  over_budget.cache_fits_scene = false;
  BatchFacts not_resident = open_facts();
  not_resident.resident_bricks = 2;
  BatchFacts many = open_facts();
  many.brick_count = many.resident_bricks = kChunkedMaxBricks + 1;
  QueryOptions no_sweep;
  no_sweep.brick_set = false;
  no_sweep.in_cache_sweep = false;
  const Case cases[] = {
      {"over budget", over_budget, QueryOptions{}, "the budget cannot hold the scene"},
      {"not resident", not_resident, QueryOptions{}, "not every brick is resident"},
      {"many bricks", many, QueryOptions{}, "too many bricks for the chunked strategies"},
      {"sweep off", open_facts(), no_sweep, "every brick resident, few bricks; the in-cache sweep is off"},
  };
  for (const Case& c : cases) {
    const BatchPlan plan = plan_batch(c.options, c.facts);
    EXPECT_EQ(plan.strategy, BatchStrategy::kQueued) << c.name;
    EXPECT_EQ(plan.reason, c.reason) << c.name;
  }
}

TEST(BatchPlanner, TheSetIsTriedBeforeTheSweepIsConsidered) {
  // The sweep being off does not stop the set.
  QueryOptions options;
  options.in_cache_sweep = false;
  EXPECT_EQ(plan_batch(options, open_facts()).strategy, BatchStrategy::kResidentSet);
  // Nor does the set being chosen depend on trace-ahead or strict mode.
  options.trace_ahead = false;
  options.strict = true;
  EXPECT_EQ(plan_batch(options, open_facts()).strategy, BatchStrategy::kResidentSet);
}

TEST(BatchPlanner, StrategiesHaveNames) {
  EXPECT_EQ(strategy_name(BatchStrategy::kSequential), "sequential");
  EXPECT_EQ(strategy_name(BatchStrategy::kResidentSet), "resident set");
  EXPECT_EQ(strategy_name(BatchStrategy::kInCacheSweep), "in-cache sweep");
  EXPECT_EQ(strategy_name(BatchStrategy::kQueued), "queued");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
