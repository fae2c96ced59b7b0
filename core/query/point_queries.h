// Point queries out of core: the closest point of the scene to each point
// (Open3D's compute_closest_points, and compute_distance from it), and
// occupancy by ray parity (compute_occupancy; signed distance = distance
// with the sign of occupancy).
//
// Closest points, in two brick-major rounds through the same cache as rays:
//   1. each point's nearest brick box (a pruned walk of the upper
//      hierarchy); the points are grouped by that brick and each brick is
//      taken once and searched for its points (BrickAccel::closest_points);
//   2. every other brick whose box is no farther than the point's best so
//      far (<=: a tie with a smaller id must be seen) is a candidate; the
//      (brick, point) pairs are grouped by brick, each brick taken once, and
//      each pair's answer kept apart, then the nearest per point is kept by
//      closest_is_better. The answer is the minimum over every brick that
//      could hold it, whatever the order: bitwise the same under any budget.
//
// Occupancy: a point is inside when a ray from it crosses the scene's
// surfaces an odd number of times (every-hit counts, watertight). A ray
// that meets an edge or a vertex (a barycentric within 1e-6 of the
// boundary) or starts on the surface cannot be trusted; the point is cast
// again along the next of kOccupancyDirections fixed directions, and when
// every direction meets one, the majority of their parities decides.
// Exact on closed, non-intersecting meshes; on an open mesh a point is
// "inside" when rays from it leave through an odd number of surfaces, as
// Open3D's.
//
// Thread-safety: as QueryEngine (the caller's).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/accel/brick_queries.h"
#include "core/cache/brick_cache.h"
#include "core/query/visit_stats.h"
#include "core/store/scene_store.h"
#include "core/util/status.h"

namespace outcore {

inline constexpr int kOccupancyDirections = 5;

struct PointQueryContext {
  const SceneStore& store;
  BrickCache& cache;
  BatchTally& tally;
  bool strict = false;
};

// A point is valid when its coordinates are finite and within the rays'
// limit (kLargestRayComponent); nullptr or the reason.
const char* point_problem(const Vec3f& point);

// The indices of the valid points (point_problem), in order; an invalid one
// is counted in `invalid`, or is INVALID_ARGUMENT naming it under strict.
Expected<std::vector<uint32_t>> valid_point_ids(std::span<const Vec3f> points, bool strict,
                                                uint64_t& invalid);

// answers[i] for points[i]; an invalid point gets no answer (not found) and
// is counted, or is INVALID_ARGUMENT naming it under strict.
Status find_closest_points(PointQueryContext& ctx, std::span<const Vec3f> points,
                           std::span<ClosestPoint> answers);

// The fixed directions of the occupancy rays (unit, none along an axis or a
// diagonal, so that axis-aligned meshes do not put edges in their way).
Vec3f occupancy_direction(int round);

// Whether one occupancy ray's hits can be trusted, and its parity.
struct ParityVerdict {
  bool trusted = true;
  bool odd = false;
};
ParityVerdict parity_of(std::span<const RayHitRecord> hits);

}  // namespace outcore
