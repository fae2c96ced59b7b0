#include "core/query/query_stats.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Every figure set to a value of its own: uint64 ones 1, 2, 3, ... and
// doubles 0.25, 0.75, 1.25, ... in list order, times `scale`.
QueryStats numbered(uint64_t scale = 1) {
  QueryStats stats;
  uint64_t count = 1;
  double seconds = 0.25;
  for_each_field(stats, [&](const StatsField&, auto& value) {
    if constexpr (std::is_same_v<std::remove_reference_t<decltype(value)>, double>) {
      value = seconds * static_cast<double>(scale);
      seconds += 0.5;
    } else {
      value = count * scale;
      ++count;
    }
  });
  return stats;
}

// The --stats-json format, keys, order and nesting, as before the one list
// (tests and the Python client read it).
TEST(QueryStatsList, JsonKeepsItsKeysOrderAndShape) {
  QueryStats stats;
  uint64_t u = 1;
  stats.rays = u++, stats.invalid_rays = u++, stats.rays_hit = u++, stats.upper_nodes_visited = u++;
  stats.brick_visits = u++, stats.rays_in_brick_set = u++, stats.rays_traced_ahead = u++;
  stats.proxy_tests = u++, stats.bricks_skipped_by_proxy = u++, stats.proxy_bytes = u++;
  stats.brick_acquisitions = u++, stats.cache_hits = u++, stats.cache_misses = u++;
  stats.brick_builds = u++, stats.evictions = u++, stats.subtree_loads = u++;
  stats.subtree_loads_checked = u++, stats.subtree_loads_kept = u++, stats.subtree_writes = u++;
  stats.subtree_rejects = u++, stats.subtree_bytes_read = u++, stats.subtree_bytes_written = u++;
  stats.peak_bytes_resident = u++, stats.cache_budget_bytes = u++;
  stats.seconds_total = 0.25, stats.seconds_upper = 0.75, stats.seconds_build = 1.25;
  stats.seconds_brick = 1.75, stats.seconds_proxy = 2.25, stats.seconds_brick_builds = 2.75;
  stats.seconds_subtree_loads = 3.25;
  stats.rays_entering_no_brick = 99;  // added after the list was made: its number is apart
  stats.brick_visits_without_hit = 98, stats.bricks_skipped_by_bound = 97;  // so were these
  stats.brick_rebuilds = 96, stats.builds_bvh = 95, stats.builds_grid = 94;
  stats.dynamic_version = 93, stats.dynamic_instances = 92, stats.rays_hit_only_dynamic = 91;
  stats.seconds_dynamic = 3.75;
  stats.subtree_loads_recycled = 90;
  EXPECT_EQ(stats.to_json(),
            R"({"rays":1,"invalid_rays":2,"rays_hit":3,"upper_nodes_visited":4,"rays_entering_no_brick":99,)"
            R"("brick_visits":5,"brick_visits_without_hit":98,)"
            R"("rays_in_brick_set":6,"proxy_tests":8,"bricks_skipped_by_proxy":9,)"
            R"("bricks_skipped_by_bound":97,"proxy_bytes":10,)"
            R"("rays_traced_ahead":7,"brick_acquisitions":11,"cache_hits":12,"cache_misses":13,)"
            R"("brick_builds":14,"brick_rebuilds":96,"brick_builds_by_structure":{"embree":0,"bvh":95,)"
            R"("kdtree":0,"bsp":0,"grid":94,"hgrid":0,"octree":0,"quadtree":0,"reference":0},)"
            R"("evictions":15,"subtree_loads":16,"subtree_loads_checked":17,)"
            R"("subtree_loads_kept":18,"subtree_loads_recycled":90,"subtree_writes":19,"subtree_rejects":20,)"
            R"("subtree_bytes_read":21,"subtree_bytes_written":22,)"
            R"("dynamic":{"version":93,"instances":92,"rays_hit_only_dynamic":91},)"
            R"("peak_bytes_resident":23,"cache_budget_bytes":24,)"
            R"("seconds":{"total":0.25,"upper":0.75,"build":1.25,"brick":1.75,"proxy":2.25,)"
            R"("brick_builds_summed":2.75,"subtree_loads_summed":3.25,"dynamic":3.75},"rays_per_second":4})");
  EXPECT_EQ(QueryStats().to_json(),
            R"({"rays":0,"invalid_rays":0,"rays_hit":0,"upper_nodes_visited":0,"rays_entering_no_brick":0,)"
            R"("brick_visits":0,"brick_visits_without_hit":0,)"
            R"("rays_in_brick_set":0,"proxy_tests":0,"bricks_skipped_by_proxy":0,)"
            R"("bricks_skipped_by_bound":0,"proxy_bytes":0,)"
            R"("rays_traced_ahead":0,"brick_acquisitions":0,"cache_hits":0,"cache_misses":0,)"
            R"("brick_builds":0,"brick_rebuilds":0,"brick_builds_by_structure":{"embree":0,"bvh":0,)"
            R"("kdtree":0,"bsp":0,"grid":0,"hgrid":0,"octree":0,"quadtree":0,"reference":0},)"
            R"("evictions":0,"subtree_loads":0,"subtree_loads_checked":0,)"
            R"("subtree_loads_kept":0,"subtree_loads_recycled":0,"subtree_writes":0,"subtree_rejects":0,)"
            R"("subtree_bytes_read":0,"subtree_bytes_written":0,)"
            R"("dynamic":{"version":0,"instances":0,"rays_hit_only_dynamic":0},)"
            R"("peak_bytes_resident":0,"cache_budget_bytes":0,)"
            R"("seconds":{"total":0,"upper":0,"build":0,"brick":0,"proxy":0,)"
            R"("brick_builds_summed":0,"subtree_loads_summed":0,"dynamic":0},"rays_per_second":0})");
}

// Counts and times add up; the engine's state seen by the queries (the
// cache's peak and budget, the proxies' size) is the larger one's.
TEST(QueryStatsList, AddingSumsCountsAndTakesTheLargerState) {
  const QueryStats one = numbered(1);
  const QueryStats three = numbered(3);
  QueryStats sum = one;
  sum += three;
  const std::vector<std::string> maxed = {"proxy_bytes", "dynamic_version", "dynamic_instances",
                                          "peak_bytes_resident", "cache_budget_bytes"};
  QueryStats want = numbered(4);
  want.proxy_bytes = three.proxy_bytes;
  want.dynamic_version = three.dynamic_version;
  want.dynamic_instances = three.dynamic_instances;
  want.peak_bytes_resident = three.peak_bytes_resident;
  want.cache_budget_bytes = three.cache_budget_bytes;
  EXPECT_EQ(sum.to_json(), want.to_json());
  std::vector<std::string> listed_max;
  for_each_field(sum, [&](const StatsField& field, const auto&) {
    if (field.combine == StatsCombine::kMax) listed_max.push_back(field.name);
  });
  EXPECT_EQ(listed_max, maxed);
  // Max is order-independent and add() is +=.
  QueryStats other = three;
  other.add(one);
  EXPECT_EQ(other.to_json(), sum.to_json());
  EXPECT_EQ(sum.seconds_total, 4 * 0.25);
}

TEST(QueryStatsList, EveryFigureHasAKeyAndTheListCountsThem) {
  std::size_t fields = 0;
  const QueryStats stats;
  for_each_field(stats, [&](const StatsField& field, const auto&) {
    EXPECT_NE(std::string(field.json_key), "") << field.name;
    // Only sums travel per reply (the client adds replies up).
    if (field.wire == StatsWire::kYes) {
      EXPECT_EQ(field.combine, StatsCombine::kSum) << field.name;
    }
    ++fields;
  });
  EXPECT_EQ(fields, kQueryStatsFieldCount);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
