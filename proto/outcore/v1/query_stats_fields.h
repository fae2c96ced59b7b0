// The figures outcore.v1.QueryStats (scene_query.proto) carries, each under
// the name it has in outcore::QueryStats (core/query/query_stats.h), in field
// order: OUTCORE_WIRE_QUERY_STATS(X) expands X(name) for each. It is the
// wire's subset of OUTCORE_QUERY_STATS, kept here in proto order because the
// proto decides it: query_stats_wire.h maps with it (server and C++ client)
// and checks at compile time that it names exactly the figures the one list
// marks as on the wire (all sums); a test checks it against the message
// (tests/server_api_test.cpp).
//
// Thread-safety: a macro; no state.
#pragma once

// clang-format off
#define OUTCORE_WIRE_QUERY_STATS(X) \
  X(rays)                           \
  X(invalid_rays)                   \
  X(rays_hit)                       \
  X(brick_visits)                   \
  X(brick_acquisitions)             \
  X(cache_hits)                     \
  X(cache_misses)                   \
  X(brick_builds)                   \
  X(evictions)                      \
  X(seconds_total)                  \
  X(seconds_build)                  \
  X(upper_nodes_visited)            \
  X(rays_traced_ahead)              \
  X(proxy_tests)                    \
  X(bricks_skipped_by_proxy)        \
  X(subtree_loads)                  \
  X(subtree_writes)                 \
  X(subtree_rejects)                \
  X(subtree_bytes_read)             \
  X(subtree_bytes_written)          \
  X(seconds_upper)                  \
  X(seconds_brick)                  \
  X(seconds_proxy)                  \
  X(seconds_brick_builds)           \
  X(seconds_subtree_loads)          \
  X(rays_in_brick_set)              \
  X(subtree_loads_checked)          \
  X(subtree_loads_kept)             \
  X(rays_entering_no_brick)         \
  X(brick_visits_without_hit)       \
  X(bricks_skipped_by_bound)        \
  X(subtree_loads_recycled)
// clang-format on
