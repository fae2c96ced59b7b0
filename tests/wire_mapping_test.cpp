// The engine's figures on the wire (proto/outcore/v1/query_stats_wire.h) and
// in the server's counters (server/service_counters.h, wire_mapping.h), all
// driven by the one list OUTCORE_QUERY_STATS.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <gtest/gtest.h>

#include <string>
#include <type_traits>

#include "core/query/query_stats.h"
#include "proto/outcore/v1/query_stats_wire.h"
#include "server/service_counters.h"
#include "server/wire_mapping.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Every figure a value of its own (uint64: 1, 2, ...; doubles: 0.5, 1.5, ...).
QueryStats numbered() {
  QueryStats stats;
  uint64_t count = 1;
  double seconds = 0.5;
  for_each_field(stats, [&](const StatsField&, auto& value) {
    if constexpr (std::is_same_v<std::remove_reference_t<decltype(value)>, double>) {
      value = seconds;
      seconds += 1;
    } else {
      value = count++;
    }
  });
  return stats;
}

TEST(WireMapping, EveryWireFigureRoundTripsAndTheOthersStayOff) {
  const QueryStats stats = numbered();
  v1::QueryStats wire;
  wire::to_wire(stats, &wire);
  // Every field of the message is filled (each figure is non-zero).
  const google::protobuf::Reflection* reflection = wire.GetReflection();
  const google::protobuf::Descriptor* message = v1::QueryStats::descriptor();
  for (int i = 0; i < message->field_count(); ++i) {
    EXPECT_TRUE(reflection->HasField(wire, message->field(i))) << message->field(i)->name();
  }
  const QueryStats back = wire::from_wire(wire);
  const auto expect_same = [&](const StatsField& field, const auto& value) {
    QueryStats copy = back;
    bool seen = false;
    for_each_field(copy, [&](const StatsField& f, const auto& got) {
      if (std::string(f.name) != field.name) return;
      seen = true;
      if (field.wire == StatsWire::kYes) {
        EXPECT_EQ(static_cast<double>(got), static_cast<double>(value)) << field.name;
      } else {
        EXPECT_EQ(static_cast<double>(got), 0.0) << field.name << " is not on the wire";
      }
    });
    EXPECT_TRUE(seen) << field.name;
  };
  for_each_field(stats, expect_same);

  // Adding on the wire is adding in the engine's figures.
  wire::add_to_wire(stats, &wire);
  QueryStats twice = stats;
  twice += stats;
  EXPECT_EQ(wire::from_wire(wire).seconds_brick, twice.seconds_brick);
  EXPECT_EQ(wire::from_wire(wire).rays_in_brick_set, twice.rays_in_brick_set);
  EXPECT_EQ(wire.subtree_loads_kept(), 2 * stats.subtree_loads_kept);
  EXPECT_EQ(wire.subtree_loads_recycled(), 2 * stats.subtree_loads_recycled);
}

TEST(WireMapping, TheServerSumsItsFiguresAndReportsThemInServerStats) {
  server::AtomicServiceCounters counters;
  const QueryStats stats = numbered();
  counters.add_answered(stats);
  counters.add_answered(stats);
  counters.count_request(false, false);
  counters.count_request(true, true);
  const server::ServiceCounters c = counters.snapshot();
  EXPECT_EQ(c.requests, 2u);
  EXPECT_EQ(c.failed_requests, 1u);
  EXPECT_EQ(c.cancelled_requests, 1u);
  EXPECT_EQ(c.answered.rays, 2 * stats.rays);
  EXPECT_EQ(c.answered.rays_hit, 2 * stats.rays_hit);
  EXPECT_EQ(c.answered.invalid_rays, 2 * stats.invalid_rays);
  EXPECT_EQ(c.answered.brick_visits, 2 * stats.brick_visits);
  EXPECT_EQ(c.answered.proxy_tests, 2 * stats.proxy_tests);
  EXPECT_EQ(c.answered.bricks_skipped_by_proxy, 2 * stats.bricks_skipped_by_proxy);
  EXPECT_EQ(c.answered.rays_traced_ahead, 2 * stats.rays_traced_ahead);
  EXPECT_EQ(c.answered.rays_in_brick_set, 2 * stats.rays_in_brick_set);
  EXPECT_NEAR(c.answered.seconds_total, 2 * stats.seconds_total, 1e-9);
  EXPECT_EQ(c.answered.cache_hits, 0u) << "ServerStats takes the cache's own counters";

  v1::ServerStats out;
  server::set_answered_sums(c.answered, &out);
  EXPECT_EQ(out.rays(), c.answered.rays);
  EXPECT_EQ(out.rays_hit(), c.answered.rays_hit);
  EXPECT_EQ(out.invalid_rays(), c.answered.invalid_rays);
  EXPECT_EQ(out.seconds_tracing(), c.answered.seconds_total);
  EXPECT_EQ(out.brick_visits(), c.answered.brick_visits);
  EXPECT_EQ(out.proxy_tests(), c.answered.proxy_tests);
  EXPECT_EQ(out.bricks_skipped_by_proxy(), c.answered.bricks_skipped_by_proxy);
  EXPECT_EQ(out.rays_traced_ahead(), c.answered.rays_traced_ahead);
  EXPECT_EQ(out.rays_in_brick_set(), c.answered.rays_in_brick_set);
  EXPECT_EQ(out.cache_hits(), 0u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
