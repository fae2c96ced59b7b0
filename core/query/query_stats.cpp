#include "core/query/query_stats.h"

#include <algorithm>
#include <cstdio>
#include <string_view>

#include "core/util/json_writer.h"

namespace outcore {

QueryStats& QueryStats::operator+=(const QueryStats& other) {
#define OUTCORE_STATS_COMBINE(type, name, object, key, combine, ...) \
  if constexpr (StatsCombine::combine == StatsCombine::kSum) {       \
    name += other.name;                                              \
  } else {                                                           \
    name = std::max(name, other.name);                               \
  }
  OUTCORE_QUERY_STATS(OUTCORE_STATS_COMBINE)
#undef OUTCORE_STATS_COMBINE
  return *this;
}

std::string QueryStats::to_json() const {
  JsonWriter j;
  j.begin_object();
  // A nested object's figures are listed together: it opens at the first.
  std::string_view open_object;
  for_each_field(*this, [&](const StatsField& field, const auto& value) {
    if (open_object != field.json_object) {
      if (!open_object.empty()) j.end_object();
      open_object = field.json_object;
      if (!open_object.empty()) j.key(open_object).begin_object();
    }
    j.field(field.json_key, value);
  });
  if (!open_object.empty()) j.end_object();
  j.field("rays_per_second", seconds_total > 0 ? rays / seconds_total : 0.0);
  j.end_object();
  return j.str();
}

std::string QueryStats::to_text() const {
  char buf[1024];
  std::snprintf(
      buf, sizeof buf,
      "rays %llu (%llu hit, %llu invalid) in %.3f s = %.2f M rays/s\n"
      "  upper: %llu nodes visited, %.3f s first pass, %llu rays entering no brick\n"
      "  bricks: %llu ray visits (%llu traced ahead, %llu without a hit), %llu acquisitions (%llu hits, %llu "
      "misses), %llu "
      "builds, %llu evictions\n"
      "  cache: peak %.1f MiB of %.1f MiB budget\n"
      "  time: build/wait %.3f s, brick traversal %.3f s\n",
      static_cast<unsigned long long>(rays), static_cast<unsigned long long>(rays_hit),
      static_cast<unsigned long long>(invalid_rays), seconds_total,
      seconds_total > 0 ? rays / seconds_total / 1e6 : 0.0,
      static_cast<unsigned long long>(upper_nodes_visited), seconds_upper,
      static_cast<unsigned long long>(rays_entering_no_brick), static_cast<unsigned long long>(brick_visits),
      static_cast<unsigned long long>(rays_traced_ahead),
      static_cast<unsigned long long>(brick_visits_without_hit),
      static_cast<unsigned long long>(brick_acquisitions), static_cast<unsigned long long>(cache_hits),
      static_cast<unsigned long long>(cache_misses), static_cast<unsigned long long>(brick_builds),
      static_cast<unsigned long long>(evictions), peak_bytes_resident / 1048576.0,
      cache_budget_bytes / 1048576.0, seconds_build, seconds_brick);
  std::string text = buf;
  if (rays_in_brick_set > 0) {
    std::snprintf(
        buf, sizeof buf,
        "  one structure over all resident bricks (resident set): %llu rays (brick visits not counted)\n",
        static_cast<unsigned long long>(rays_in_brick_set));
    text += buf;
  }
  if (dynamic_instances > 0) {
    std::snprintf(
        buf, sizeof buf,
        "  dynamic layer: version %llu, %llu instances, %llu rays hit only dynamic geometry, %.3f s\n",
        static_cast<unsigned long long>(dynamic_version), static_cast<unsigned long long>(dynamic_instances),
        static_cast<unsigned long long>(rays_hit_only_dynamic), seconds_dynamic);
    text += buf;
  }
  if (proxy_bytes > 0) {
    const uint64_t candidates = brick_visits + bricks_skipped_by_proxy;
    std::snprintf(buf, sizeof buf,
                  "  proxies: %llu of %llu brick visits skipped (%.1f %%), %llu tests, %.3f s (all threads), "
                  "%.2f MiB resident\n",
                  static_cast<unsigned long long>(bricks_skipped_by_proxy),
                  static_cast<unsigned long long>(candidates),
                  candidates > 0 ? 100.0 * bricks_skipped_by_proxy / candidates : 0.0,
                  static_cast<unsigned long long>(proxy_tests), seconds_proxy, proxy_bytes / 1048576.0);
    text += buf;
  } else {
    text += "  proxies: off\n";
  }
  if (subtree_loads + subtree_writes + subtree_rejects > 0) {
    std::snprintf(
        buf, sizeof buf,
        "  subtree tier: %llu loads (%llu checked in full, %llu on kept copies, %llu recycled; %.1f MiB, "
        "%.3f s), %llu writes (%.1f MiB), %llu rejected; builds %.3f s\n",
        static_cast<unsigned long long>(subtree_loads),
        static_cast<unsigned long long>(subtree_loads_checked),
        static_cast<unsigned long long>(subtree_loads_kept),
        static_cast<unsigned long long>(subtree_loads_recycled), subtree_bytes_read / 1048576.0,
        seconds_subtree_loads, static_cast<unsigned long long>(subtree_writes),
        subtree_bytes_written / 1048576.0, static_cast<unsigned long long>(subtree_rejects),
        seconds_brick_builds);
    text += buf;
  }
  return text;
}

}  // namespace outcore
