#include "core/query/point_queries.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "core/query/brick_visit.h"
#include "core/query/strategy.h"
#include "core/ray/ray_types.h"
#include "core/util/cancellation.h"

namespace outcore {

namespace {

// A point's walk of the upper hierarchy keeps at most one pending sibling
// per level.
constexpr uint32_t kUpperStack = 256;

// The brick whose box is nearest to p (ties to the smaller brick id).
uint32_t nearest_brick(const UpperHierarchy& upper, const Vec3d& p) {
  struct Entry {
    uint32_t node;
    double distance_squared;
  };
  Entry stack[kUpperStack];
  uint32_t size = 0;
  stack[size++] = {0, distance_squared_to_box(p, upper.nodes[0].bounds)};
  uint32_t best = kInvalidId;
  double best_d2 = std::numeric_limits<double>::infinity();
  while (size > 0) {
    const Entry entry = stack[--size];
    if (entry.distance_squared > best_d2) continue;
    const UpperNode& node = upper.nodes[entry.node];
    if (node.is_leaf != 0) {
      if (entry.distance_squared < best_d2 || node.child_or_brick < best) {
        best = node.child_or_brick;
        best_d2 = entry.distance_squared;
      }
      continue;
    }
    const uint32_t left = node.child_or_brick;
    Entry a{left, distance_squared_to_box(p, upper.nodes[left].bounds)};
    Entry b{left + 1, distance_squared_to_box(p, upper.nodes[left + 1].bounds)};
    if (a.distance_squared < b.distance_squared) std::swap(a, b);  // nearer on top
    stack[size++] = a;
    stack[size++] = b;
  }
  return best;
}

// Every brick other than `except` whose box is within d2 of p.
void bricks_within(const UpperHierarchy& upper, const Vec3d& p, double d2, uint32_t except, uint32_t point,
                   std::vector<std::pair<uint32_t, uint32_t>>& pairs) {
  uint32_t stack[kUpperStack];
  uint32_t size = 0;
  stack[size++] = 0;
  while (size > 0) {
    const UpperNode& node = upper.nodes[stack[--size]];
    if (distance_squared_to_box(p, node.bounds) > d2) continue;
    if (node.is_leaf != 0) {
      if (node.child_or_brick != except) pairs.emplace_back(node.child_or_brick, point);
      continue;
    }
    stack[size++] = node.child_or_brick;
    stack[size++] = node.child_or_brick + 1;
  }
}

// Groups of consecutive pairs with the same brick.
std::vector<std::pair<std::size_t, std::size_t>> brick_groups(
    const std::vector<std::pair<uint32_t, uint32_t>>& pairs) {
  std::vector<std::pair<std::size_t, std::size_t>> groups;
  for (std::size_t begin = 0; begin < pairs.size();) {
    std::size_t end = begin + 1;
    while (end < pairs.size() && pairs[end].first == pairs[begin].first) ++end;
    groups.emplace_back(begin, end);
    begin = end;
  }
  return groups;
}

// Searches each group's brick for its pairs' points, each pair starting
// from (and writing) found[k].
Status search_groups(PointQueryContext& ctx, std::span<const Vec3f> points,
                     const std::vector<std::pair<uint32_t, uint32_t>>& pairs,
                     std::vector<ClosestPoint>& found) {
  const auto groups = brick_groups(pairs);
  std::vector<PinningTask> tasks(groups.size());
  tbb::parallel_for(std::size_t{0}, groups.size(), std::size_t{1}, [&](std::size_t g) {
    if (cancel_requested()) return;
    const auto [begin, end] = groups[g];
    const uint32_t brick = pairs[begin].first;
    tbb::this_task_arena::isolate([&] {
      std::optional<PinnedBrick> pin = pin_for(ctx.cache, brick, end - begin, tasks[g]);
      if (!pin) return;
      std::vector<Vec3f> local_points(end - begin);
      std::vector<uint32_t> ids(end - begin);
      for (std::size_t k = begin; k < end; ++k) {
        local_points[k - begin] = points[pairs[k].second];
        ids[k - begin] = static_cast<uint32_t>(k - begin);
      }
      pin->accel().closest_points(ids, local_points.data(), found.data() + begin);
    });
  });
  if (cancel_requested()) return batch_interrupted();
  for (const PinningTask& task : tasks) {
    OUTCORE_RETURN_IF_ERROR(task.status);
    merge_task(task, ctx.tally);
    ctx.tally.stats.seconds_build += task.build_seconds;
  }
  ctx.tally.stats.brick_visits += pairs.size();
  return Status::Ok();
}

}  // namespace

const char* point_problem(const Vec3f& point) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(point[a])) return "a coordinate is not finite";
    if (std::abs(point[a]) > kLargestRayComponent) return "a coordinate is beyond +-1.844e18";
  }
  return nullptr;
}

Expected<std::vector<uint32_t>> valid_point_ids(std::span<const Vec3f> points, bool strict,
                                                uint64_t& invalid) {
  std::vector<uint32_t> ids;
  ids.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (const char* problem = point_problem(points[i])) {
      if (strict) return invalid_argument("point " + std::to_string(i) + ": " + problem);
      ++invalid;
      continue;
    }
    ids.push_back(static_cast<uint32_t>(i));
  }
  return ids;
}

Status find_closest_points(PointQueryContext& ctx, std::span<const Vec3f> points,
                           std::span<ClosestPoint> answers) {
  QueryStats& stats = ctx.tally.stats;
  const UpperHierarchy& upper = ctx.store.manifest().upper;
  if (upper.depth() >= kUpperStack / 2)
    return internal_error("upper hierarchy deeper than point walks allow");
  const std::size_t n = points.size();
  std::fill(answers.begin(), answers.end(), ClosestPoint{});
  OUTCORE_ASSIGN_OR_RETURN(const std::vector<uint32_t> valid,
                           valid_point_ids(points, ctx.strict, stats.invalid_rays));
  std::vector<std::pair<uint32_t, uint32_t>> pairs;  // (brick, point)
  if (!upper.empty()) {
    pairs.reserve(valid.size());
    for (const uint32_t i : valid) pairs.emplace_back(kInvalidId, i);
  }
  // Round 1: each point's nearest brick.
  const auto t_upper = Clock::now();
  tbb::parallel_for(std::size_t{0}, pairs.size(), [&](std::size_t k) {
    pairs[k].first = nearest_brick(upper, Vec3d(points[pairs[k].second]));
  });
  std::stable_sort(pairs.begin(), pairs.end());
  stats.seconds_upper += seconds_since(t_upper);
  std::vector<ClosestPoint> found(pairs.size());
  const auto t_brick = Clock::now();
  OUTCORE_RETURN_IF_ERROR(search_groups(ctx, points, pairs, found));
  for (std::size_t k = 0; k < pairs.size(); ++k) answers[pairs[k].second] = found[k];
  // Round 2: every other brick that may hold a point as near.
  std::vector<std::pair<uint32_t, uint32_t>> first = std::move(pairs);
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> per_chunk((first.size() + 1023) / 1024);
  tbb::parallel_for(std::size_t{0}, per_chunk.size(), [&](std::size_t c) {
    for (std::size_t k = c * 1024; k < std::min(first.size(), (c + 1) * 1024); ++k) {
      const uint32_t i = first[k].second;
      bricks_within(upper, Vec3d(points[i]), answers[i].distance_squared, first[k].first, i, per_chunk[c]);
    }
  });
  pairs.clear();
  for (const auto& chunk : per_chunk) pairs.insert(pairs.end(), chunk.begin(), chunk.end());
  std::sort(pairs.begin(), pairs.end());
  found.assign(pairs.size(), ClosestPoint{});
  for (std::size_t k = 0; k < pairs.size(); ++k) found[k] = answers[pairs[k].second];
  OUTCORE_RETURN_IF_ERROR(search_groups(ctx, points, pairs, found));
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    ClosestPoint& answer = answers[pairs[k].second];
    const ClosestPoint& candidate = found[k];
    if (closest_is_better(candidate.distance_squared, candidate.geometry_id, candidate.primitive_id, answer))
      answer = candidate;
  }
  stats.seconds_brick += seconds_since(t_brick);
  for (std::size_t i = 0; i < n; ++i) stats.rays_hit += answers[i].found();
  return Status::Ok();
}

Vec3f occupancy_direction(int round) {
  static constexpr float kDirections[kOccupancyDirections][3] = {{0.26171f, 0.88130f, 0.39343f},
                                                                 {-0.64213f, 0.19970f, 0.74020f},
                                                                 {0.45131f, -0.72710f, 0.51740f},
                                                                 {-0.31190f, -0.40270f, -0.86070f},
                                                                 {0.89120f, 0.31210f, -0.32900f}};
  const float* d = kDirections[round % kOccupancyDirections];
  return Vec3f(normalize(Vec3d(d[0], d[1], d[2])));
}

ParityVerdict parity_of(std::span<const RayHitRecord> hits) {
  constexpr float kEdge = 1e-6f;
  ParityVerdict verdict;
  verdict.odd = hits.size() % 2 == 1;
  for (const RayHitRecord& r : hits) {
    const float u = r.hit.u, v = r.hit.v;
    if (u <= kEdge || v <= kEdge || u + v >= 1.0f - kEdge || r.hit.t <= 0.0f) verdict.trusted = false;
  }
  return verdict;
}

}  // namespace outcore
