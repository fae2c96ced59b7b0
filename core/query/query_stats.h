// QueryStats: the figures one query (or a sum of queries) reports: rays,
// hits, visits, cache and subtree-tier activity, and where the time went.
// to_json() is the --stats-json format; to_text() the --stats summary.
//
// OUTCORE_QUERY_STATS below is the one list of these figures: the struct's
// members, to_json, the combining of two queries' figures (operator+=), the
// wire mapping (proto/outcore/v1/query_stats_wire.h) and the server's
// counters all come from it, so a figure added there reaches every one.
//
// Thread-safety: a plain value.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>

namespace outcore {

// How two queries' values of a figure combine into their sum's.
enum class StatsCombine {
  kSum,  // counts and times of the queries themselves
  kMax,  // the engine's state seen by them (peak, budget, proxies' size)
};

// Where a figure travels besides --stats-json.
enum class StatsWire {
  kNo,   // per process: the server reports it in ServerStats instead
  kYes,  // in outcore.v1.QueryStats, per reply (a sum: kSum only)
};

// Whether the server sums the figure over the requests it answers and
// reports the sum in ServerStats under the same name (GetStats).
enum class StatsServer { kNo, kYes };

// X(type, name, json_object, json_key, combine, wire, server) for each figure,
// in --stats-json order. json_object is "" for a top-level key, else the
// nested object's name (its figures are listed together). The JSON ends with
// rays_per_second, derived from rays and seconds_total.
//
// brick_builds, evictions, the subtree_* figures and seconds_brick_builds /
// seconds_subtree_loads are cache-wide during the query (other batches'
// builds included); seconds_total is ServerStats.seconds_tracing (summed by
// the server under that name).
// clang-format off
// builds_<structure> for each brick structure the factory names (auto is not
// one: its builds are counted as the structure it chose).
#define OUTCORE_STRUCTURE_BUILDS(X)                                                                 \
  X(uint64_t, builds_embree,    "brick_builds_by_structure", "embree",    kSum, kNo, kNo)            \
  X(uint64_t, builds_bvh,       "brick_builds_by_structure", "bvh",       kSum, kNo, kNo)            \
  X(uint64_t, builds_kdtree,    "brick_builds_by_structure", "kdtree",    kSum, kNo, kNo)            \
  X(uint64_t, builds_bsp,       "brick_builds_by_structure", "bsp",       kSum, kNo, kNo)            \
  X(uint64_t, builds_grid,      "brick_builds_by_structure", "grid",      kSum, kNo, kNo)            \
  X(uint64_t, builds_hgrid,     "brick_builds_by_structure", "hgrid",     kSum, kNo, kNo)            \
  X(uint64_t, builds_octree,    "brick_builds_by_structure", "octree",    kSum, kNo, kNo)            \
  X(uint64_t, builds_quadtree,  "brick_builds_by_structure", "quadtree",  kSum, kNo, kNo)            \
  X(uint64_t, builds_reference, "brick_builds_by_structure", "reference", kSum, kNo, kNo)
#define OUTCORE_QUERY_STATS(X)                                                                      \
  X(uint64_t, rays,                    "",        "rays",                    kSum, kYes, kYes)      \
  X(uint64_t, invalid_rays,            "",        "invalid_rays",            kSum, kYes, kYes)      \
  X(uint64_t, rays_hit,                "",        "rays_hit",                kSum, kYes, kYes)      \
  X(uint64_t, upper_nodes_visited,     "",        "upper_nodes_visited",     kSum, kYes, kNo)       \
  /* valid rays whose segment enters no brick's box (outside the scene's box */                      \
  /* or between its bricks): answered, misses, by their first upper walk, never */                   \
  /* queued (0 in the resident set, which has no upper walk; with only_bricks, */                     \
  /* no brick of the part) */                                                                        \
  X(uint64_t, rays_entering_no_brick,  "",        "rays_entering_no_brick",  kSum, kYes, kNo)       \
  /* (ray, brick) traversals */                                                                     \
  X(uint64_t, brick_visits,            "",        "brick_visits",            kSum, kYes, kYes)      \
  /* of those, visits that found no hit nearer than the ray had (closest */                        \
  /* hit) or left the ray unoccluded (any hit): the brick bound's false */                          \
  /* positives, plus bricks the ray crosses in front of a farther hit */                            \
  X(uint64_t, brick_visits_without_hit, "",       "brick_visits_without_hit", kSum, kYes, kYes)     \
  /* traced through the resident bricks' one scene (no visits counted) */                           \
  X(uint64_t, rays_in_brick_set,       "",        "rays_in_brick_set",       kSum, kYes, kYes)      \
  /* (ray, brick) candidates tested against a proxy; of those, visits avoided */                    \
  X(uint64_t, proxy_tests,             "",        "proxy_tests",             kSum, kYes, kYes)      \
  X(uint64_t, bricks_skipped_by_proxy, "",        "bricks_skipped_by_proxy", kSum, kYes, kYes)      \
  /* (ray, brick) candidates the brick bound (--brick-bounds sphere|obb) turned */                  \
  /* away after the upper hierarchy's box let them in */                                             \
  X(uint64_t, bricks_skipped_by_bound, "",        "bricks_skipped_by_bound", kSum, kYes, kYes)      \
  /* the engine's resident proxies (0 without) */                                                   \
  X(uint64_t, proxy_bytes,             "",        "proxy_bytes",             kMax, kNo,  kNo)       \
  /* traced at a brick before reaching it (some never do) */                                        \
  X(uint64_t, rays_traced_ahead,       "",        "rays_traced_ahead",       kSum, kYes, kYes)      \
  /* times a brick was taken from the cache */                                                      \
  X(uint64_t, brick_acquisitions,      "",        "brick_acquisitions",      kSum, kYes, kNo)       \
  X(uint64_t, cache_hits,              "",        "cache_hits",              kSum, kYes, kNo)       \
  X(uint64_t, cache_misses,            "",        "cache_misses",            kSum, kYes, kNo)       \
  X(uint64_t, brick_builds,            "",        "brick_builds",            kSum, kYes, kNo)       \
  /* of those, bricks built again as another structure (auto's refinement) */                       \
  X(uint64_t, brick_rebuilds,          "",        "brick_rebuilds",          kSum, kNo,  kNo)       \
  /* builds by the structure built (with auto: the one chosen) */                                   \
  OUTCORE_STRUCTURE_BUILDS(X)                                                                       \
  X(uint64_t, evictions,               "",        "evictions",               kSum, kYes, kNo)       \
  /* subtree tier (0 without one): misses served by loading a file; of them */                      \
  /* those checked in full (first loads), those read into their brick's */                         \
  /* kept copy and those into another evicted brick's queued one (both */                           \
  /* mapping no memory); files written; files refused (corrupt, other */                            \
  /* version, stale; each then built) */                                                            \
  X(uint64_t, subtree_loads,           "",        "subtree_loads",           kSum, kYes, kNo)       \
  X(uint64_t, subtree_loads_checked,   "",        "subtree_loads_checked",   kSum, kYes, kNo)       \
  X(uint64_t, subtree_loads_kept,      "",        "subtree_loads_kept",      kSum, kYes, kNo)       \
  X(uint64_t, subtree_loads_recycled,  "",        "subtree_loads_recycled",  kSum, kYes, kNo)       \
  X(uint64_t, subtree_writes,          "",        "subtree_writes",          kSum, kYes, kNo)       \
  X(uint64_t, subtree_rejects,         "",        "subtree_rejects",         kSum, kYes, kNo)       \
  X(uint64_t, subtree_bytes_read,      "",        "subtree_bytes_read",      kSum, kYes, kNo)       \
  X(uint64_t, subtree_bytes_written,   "",        "subtree_bytes_written",   kSum, kYes, kNo)       \
  /* the dynamic layer's version the query saw, its live instances, and */                           \
  /* rays whose answer came from it (misses the static scene left) */                               \
  X(uint64_t, dynamic_version,         "dynamic", "version",                 kMax, kNo,  kNo)       \
  X(uint64_t, dynamic_instances,       "dynamic", "instances",               kMax, kNo,  kNo)       \
  X(uint64_t, rays_hit_only_dynamic,   "dynamic", "rays_hit_only_dynamic",   kSum, kNo,  kNo)       \
  X(uint64_t, peak_bytes_resident,     "",        "peak_bytes_resident",     kMax, kNo,  kNo)       \
  X(uint64_t, cache_budget_bytes,      "",        "cache_budget_bytes",      kMax, kNo,  kNo)       \
  X(double,   seconds_total,           "seconds", "total",                   kSum, kYes, kYes)      \
  /* first upper-hierarchy pass for every ray */                                                    \
  X(double,   seconds_upper,           "seconds", "upper",                   kSum, kYes, kNo)       \
  /* waiting for bricks: load + build (or another batch's build) */                                 \
  X(double,   seconds_build,           "seconds", "build",                   kSum, kYes, kNo)       \
  /* tracing inside bricks, plus finding each ray's next brick */                                   \
  X(double,   seconds_brick,           "seconds", "brick",                   kSum, kYes, kNo)       \
  /* proxy tests, summed over threads (part of upper and brick) */                                  \
  X(double,   seconds_proxy,           "seconds", "proxy",                   kSum, kYes, kNo)       \
  /* summed over threads: store load + build of the bricks built, and */                            \
  /* subtree file load + deserialise of the bricks loaded instead */                                \
  X(double,   seconds_brick_builds,    "seconds", "brick_builds_summed",     kSum, kYes, kNo)       \
  X(double,   seconds_subtree_loads,   "seconds", "subtree_loads_summed",    kSum, kYes, kNo)       \
  /* tracing the dynamic layer (after the static scene) */                                          \
  X(double,   seconds_dynamic,         "seconds", "dynamic",                 kSum, kNo,  kNo)
// clang-format on

// What the list says about one figure.
struct StatsField {
  const char* name;
  const char* json_object;
  const char* json_key;
  StatsCombine combine;
  StatsWire wire;
  StatsServer server;
};

// query_stats_fields::NAME: the list's entry for figure NAME (compile time,
// e.g. for checks that another list names only figures that fit it).
namespace query_stats_fields {
#define OUTCORE_STATS_FIELD_INFO(type, name, object, key, combine, wire, server) \
  inline constexpr StatsField name{                                              \
      #name, object, key, StatsCombine::combine, StatsWire::wire, StatsServer::server};
OUTCORE_QUERY_STATS(OUTCORE_STATS_FIELD_INFO)
#undef OUTCORE_STATS_FIELD_INFO
}  // namespace query_stats_fields

#define OUTCORE_STATS_COUNT_FIELD(...) +1
inline constexpr std::size_t kQueryStatsFieldCount = 0 OUTCORE_QUERY_STATS(OUTCORE_STATS_COUNT_FIELD);
#undef OUTCORE_STATS_COUNT_FIELD

struct QueryStats {
#define OUTCORE_STATS_MEMBER(type, name, ...) type name = 0;
  OUTCORE_QUERY_STATS(OUTCORE_STATS_MEMBER)
#undef OUTCORE_STATS_MEMBER

  // Combines `other` into this, figure by figure as the list says (sum or max).
  QueryStats& operator+=(const QueryStats& other);
  QueryStats& add(const QueryStats& other) {
    return *this += other;
  }

  std::string to_json() const;
  std::string to_text() const;
};

// Calls f(field, value) for each figure in list order, `value` a reference
// to the member (uint64_t or double; const when `stats` is).
template <class Stats, class F>
requires std::is_same_v<std::remove_const_t<Stats>, QueryStats>
void for_each_field(Stats& stats, F&& f) {
#define OUTCORE_STATS_VISIT(type, name, ...) f(query_stats_fields::name, stats.name);
  OUTCORE_QUERY_STATS(OUTCORE_STATS_VISIT)
#undef OUTCORE_STATS_VISIT
}

}  // namespace outcore
