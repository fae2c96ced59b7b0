#include "core/cache/belady.h"

#include <algorithm>
#include <limits>
#include <set>
#include <tuple>
#include <vector>

namespace outcore {

const char* belady_rule_name(BeladyRule rule) {
  return rule == BeladyRule::kFurthestNextUse ? "furthest-next-use" : "size-weighted";
}

Expected<SimulationResult> simulate_belady(const AccessTrace& trace, const TraceProfile& profile,
                                           uint64_t budget_bytes, BeladyRule rule) {
  OUTCORE_RETURN_IF_ERROR(check_budget(trace, profile, budget_bytes));
  SimulationResult result;
  result.policy = "opt";
  result.detail = belady_rule_name(rule);
  result.budget_bytes = budget_bytes;

  const std::size_t n = trace.records.size();
  const std::size_t bricks = profile.mean_build_seconds.size();
  constexpr uint64_t kNever = std::numeric_limits<uint64_t>::max();
  // next[i]: the index of the next request of record i's brick, kNever if none.
  std::vector<uint64_t> next(n, kNever);
  {
    std::vector<uint64_t> upcoming(bricks, kNever);
    for (std::size_t i = n; i-- > 0;) {
      next[i] = upcoming[trace.records[i].brick];
      upcoming[trace.records[i].brick] = i;
    }
  }

  std::vector<uint8_t> resident(bricks, 0);
  std::vector<uint64_t> bytes_of(bricks, 0);
  std::vector<uint64_t> next_use(bricks, kNever);
  uint64_t resident_bytes = 0;
  // Furthest next use first; among never-again (or equal) ones the largest.
  std::set<std::tuple<uint64_t, uint64_t, uint32_t>> by_next;  // (next use, bytes, brick)
  std::vector<uint32_t> resident_list;                         // for the size-weighted scan
  std::vector<std::size_t> position(bricks, 0);

  const auto remove = [&](uint32_t b) {
    by_next.erase({next_use[b], bytes_of[b], b});
    const std::size_t at = position[b];
    resident_list[at] = resident_list.back();
    position[resident_list[at]] = at;
    resident_list.pop_back();
    resident[b] = 0;
    resident_bytes -= bytes_of[b];
    bytes_of[b] = 0;
    ++result.evictions;
  };
  const auto victim = [&](uint64_t now) -> uint32_t {
    if (rule == BeladyRule::kFurthestNextUse) return std::get<2>(*by_next.rbegin());
    uint32_t best = resident_list.front();
    long double best_score = -1;
    for (const uint32_t b : resident_list) {
      const long double distance = next_use[b] == kNever ? std::numeric_limits<long double>::infinity()
                                                         : static_cast<long double>(next_use[b] - now);
      const long double score = distance * static_cast<long double>(bytes_of[b]);
      if (score > best_score || (score == best_score && b < best)) {
        best = b;
        best_score = score;
      }
    }
    return best;
  };
  const auto make_room = [&](uint64_t extra, uint64_t now) {
    while (resident_bytes + extra > budget_bytes && !resident_list.empty()) remove(victim(now));
  };

  for (std::size_t i = 0; i < n; ++i) {
    const AccessRecord& r = trace.records[i];
    ++result.requests;
    if (resident[r.brick]) {
      ++result.hits;
      by_next.erase({next_use[r.brick], bytes_of[r.brick], r.brick});
      next_use[r.brick] = next[i];
      by_next.emplace(next_use[r.brick], bytes_of[r.brick], r.brick);
      continue;
    }
    const uint64_t reserve = TraceProfile::reservation(r);
    make_room(reserve, i);
    result.peak_resident_bytes = std::max(result.peak_resident_bytes, resident_bytes + reserve);
    if (r.bytes > reserve) make_room(r.bytes, i);
    resident[r.brick] = 1;
    bytes_of[r.brick] = r.bytes;
    next_use[r.brick] = next[i];
    by_next.emplace(next_use[r.brick], r.bytes, r.brick);
    position[r.brick] = resident_list.size();
    resident_list.push_back(r.brick);
    resident_bytes += r.bytes;
    result.peak_resident_bytes = std::max(result.peak_resident_bytes, resident_bytes);
    ++result.misses;
    result.bytes_built += r.bytes;
    result.build_seconds += profile.cost(r);
  }
  return result;
}

Expected<SimulationResult> simulate_opt(const AccessTrace& trace, const TraceProfile& profile,
                                        uint64_t budget_bytes) {
  OUTCORE_ASSIGN_OR_RETURN(SimulationResult best,
                           simulate_belady(trace, profile, budget_bytes, BeladyRule::kFurthestNextUse));
  bool equal_sizes = true;
  for (const AccessRecord& r : trace.records) {
    if (r.bytes != trace.records.front().bytes ||
        TraceProfile::reservation(r) != TraceProfile::reservation(trace.records.front())) {
      equal_sizes = false;
      break;
    }
  }
  if (equal_sizes) return best;
  OUTCORE_ASSIGN_OR_RETURN(SimulationResult sized,
                           simulate_belady(trace, profile, budget_bytes, BeladyRule::kSizeWeighted));
  if (std::tie(sized.misses, sized.bytes_built) < std::tie(best.misses, best.bytes_built)) return sized;
  return best;
}

}  // namespace outcore
