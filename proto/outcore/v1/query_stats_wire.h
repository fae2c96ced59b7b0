// The one mapping between outcore::QueryStats (core/query/query_stats.h) and
// the wire's outcore.v1.QueryStats, for the server (replies) and the C++
// client (summing replies). It walks the wire subset in proto field order
// (query_stats_fields.h); the checks below tie that subset to the figures
// OUTCORE_QUERY_STATS marks as on the wire, so the two lists cannot drift.
//
// Thread-safety: functions of their arguments.
#pragma once

#include "core/query/query_stats.h"
#include "outcore/v1/scene_query.pb.h"
#include "proto/outcore/v1/query_stats_fields.h"

namespace outcore::wire {

// Every figure the wire carries is marked so in the one list, and is a sum
// (a reply carries its own rays' figures; the client adds replies up).
#define OUTCORE_CHECK_WIRE_FIELD(name)                                               \
  static_assert(query_stats_fields::name.wire == StatsWire::kYes,                    \
                #name " is on the wire but not marked kYes in OUTCORE_QUERY_STATS"); \
  static_assert(query_stats_fields::name.combine == StatsCombine::kSum, #name " on the wire is no sum");
OUTCORE_WIRE_QUERY_STATS(OUTCORE_CHECK_WIRE_FIELD)
#undef OUTCORE_CHECK_WIRE_FIELD

// ... and every figure marked so is on the wire.
#define OUTCORE_COUNT_WIRE_FIELD(name) +1
#define OUTCORE_COUNT_MARKED_FIELD(type, name, object, key, combine, wire, ...) \
  +(StatsWire::wire == StatsWire::kYes ? 1 : 0)
static_assert((0 OUTCORE_WIRE_QUERY_STATS(OUTCORE_COUNT_WIRE_FIELD)) ==
                  (0 OUTCORE_QUERY_STATS(OUTCORE_COUNT_MARKED_FIELD)),
              "a figure marked kYes in OUTCORE_QUERY_STATS is missing from OUTCORE_WIRE_QUERY_STATS");
#undef OUTCORE_COUNT_MARKED_FIELD
#undef OUTCORE_COUNT_WIRE_FIELD

// The wire's figures of `stats` (the others are not carried).
inline void to_wire(const QueryStats& stats, v1::QueryStats* out) {
#define OUTCORE_SET_WIRE_FIELD(name) out->set_##name(stats.name);
  OUTCORE_WIRE_QUERY_STATS(OUTCORE_SET_WIRE_FIELD)
#undef OUTCORE_SET_WIRE_FIELD
}

// The engine's figures from the wire's; those the wire does not carry stay 0.
inline QueryStats from_wire(const v1::QueryStats& wire) {
  QueryStats stats;
#define OUTCORE_GET_WIRE_FIELD(name) stats.name = wire.name();
  OUTCORE_WIRE_QUERY_STATS(OUTCORE_GET_WIRE_FIELD)
#undef OUTCORE_GET_WIRE_FIELD
  return stats;
}

// Combines `stats` into the wire's figures in `out` as the list says.
inline void add_to_wire(const QueryStats& stats, v1::QueryStats* out) {
  QueryStats sum = from_wire(*out);
  sum += stats;
  to_wire(sum, out);
}

}  // namespace outcore::wire
