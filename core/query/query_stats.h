// QueryStats: the figures one query (or a sum of queries) reports: rays,
// hits, visits, cache and subtree-tier activity, and where the time went.
// to_json() is the --stats-json format; to_text() the --stats summary.
//
// Thread-safety: a plain value.
#pragma once

#include <cstdint>
#include <string>

namespace outcore {

struct QueryStats {
  uint64_t rays = 0;
  uint64_t invalid_rays = 0;
  uint64_t rays_hit = 0;
  uint64_t upper_nodes_visited = 0;
  uint64_t brick_visits = 0;             // (ray, brick) traversals
  uint64_t rays_in_brick_set = 0;        // traced through the resident bricks' one scene (no visits counted)
  uint64_t rays_traced_ahead = 0;        // traced at a brick before reaching it (some never do)
  uint64_t proxy_tests = 0;              // (ray, brick) candidates tested against a proxy
  uint64_t bricks_skipped_by_proxy = 0;  // of those, visits avoided (the ray cannot hit the brick)
  uint64_t proxy_bytes = 0;              // the engine's resident proxies (0 without)
  uint64_t brick_acquisitions = 0;       // times a brick was taken from the cache
  uint64_t cache_hits = 0;
  uint64_t cache_misses = 0;
  uint64_t brick_builds = 0;  // cache-wide during this query (others' batches included)
  uint64_t evictions = 0;     // likewise
  // The subtree tier, likewise cache-wide (all 0 without one): misses served
  // by loading a file instead of building, files written, their bytes, and
  // files refused (corrupt, other version, stale; each then built).
  uint64_t subtree_loads = 0;
  uint64_t subtree_loads_checked = 0;  // of the loads, those that checked the file in full (first loads)
  uint64_t subtree_loads_kept = 0;     // of the loads, those that reused a kept mapping (no open or mmap)
  uint64_t subtree_writes = 0;
  uint64_t subtree_rejects = 0;
  uint64_t subtree_bytes_read = 0;
  uint64_t subtree_bytes_written = 0;
  uint64_t peak_bytes_resident = 0;
  uint64_t cache_budget_bytes = 0;
  double seconds_total = 0;
  double seconds_upper = 0;  // first upper-hierarchy pass for every ray
  double seconds_build = 0;  // waiting for bricks: load + build (or another batch's build)
  double seconds_brick = 0;  // tracing inside bricks, plus finding each ray's next brick
  double seconds_proxy = 0;  // proxy tests, summed over threads (part of upper and brick)
  // Cache-wide, summed over threads: store load + build of the bricks built,
  // and subtree file load + deserialise of the bricks loaded instead.
  double seconds_brick_builds = 0;
  double seconds_subtree_loads = 0;

  std::string to_json() const;
  std::string to_text() const;
};

}  // namespace outcore
