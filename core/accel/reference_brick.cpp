#include "core/accel/reference_brick.h"

#include <chrono>
#include <cstdint>
#include <string>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/triangle_hit_records.h"
#include "core/ray/query_types.h"

namespace outcore {

Expected<std::unique_ptr<ReferenceBrickAccel>> ReferenceBrickAccel::build(BrickData&& brick) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = brick_build_context(brick, "reference");
  // Its own wording for too many triangles (below), so no limit here.
  OUTCORE_RETURN_IF_ERROR(check_brick_build_input(brick, what, UINT64_MAX));
  if (n > 0xfffffffeu) return out_of_range(what + ": too many triangles");
  std::unique_ptr<ReferenceBrickAccel> accel(new ReferenceBrickAccel());
  accel->triangle_count_ = static_cast<uint32_t>(n);
  keep_usable_triangles(brick);
  accel->records_ = hit_records_for(brick.triangles, brick.ids);
  accel->triangles_ = std::move(brick.triangles);
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

uint64_t ReferenceBrickAccel::memory_bytes() const {
  return kOverheadBytes + triangles_.capacity() * sizeof(Triangle) +
         records_.capacity() * sizeof(BvhHitRecord);
}

void ReferenceBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  for (const uint32_t i : ray_ids) {
    const Ray& ray = rays[i];
    Hit& best = hits[i];
    const auto prepared = DoubleTriangleTest::prepare(ray);
    uint32_t found = kInvalidId;
    TriangleHit found_hit{};
    for (uint32_t k = 0; k < triangles_.size(); ++k) {
      const float tfar = ray.tfar < best.t ? ray.tfar : best.t;
      TriangleHit h;
      if (!DoubleTriangleTest::hit(prepared, triangles_[k], ray.tnear, tfar, h)) continue;
      if (!hit_is_better(h.t, records_[k].geometry_id, records_[k].primitive_id, best)) continue;
      best.t = h.t;
      best.geometry_id = records_[k].geometry_id;
      best.primitive_id = records_[k].primitive_id;
      found = k;
      found_hit = h;
    }
    if (found == kInvalidId) continue;
    best.u = found_hit.u;
    best.v = found_hit.v;
    best.normal = records_[found].normal;
  }
}

void ReferenceBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays,
                                   uint8_t* occluded) const {
  for (const uint32_t i : ray_ids) {
    if (occluded[i] != 0) continue;
    const auto prepared = DoubleTriangleTest::prepare(rays[i]);
    for (const Triangle& tri : triangles_) {
      TriangleHit h;
      if (DoubleTriangleTest::hit(prepared, tri, rays[i].tnear, rays[i].tfar, h)) {
        occluded[i] = 1;
        break;
      }
    }
  }
}

void ReferenceBrickAccel::all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                                   std::vector<RayHitRecord>& out) const {
  all_hits_by_scan<DoubleTriangleTest>(triangles_, records_, ray_ids, rays, out);
}

void ReferenceBrickAccel::closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                                         ClosestPoint* best) const {
  closest_points_by_scan(triangles_, records_, point_ids, points, best);
}

Expected<std::unique_ptr<BrickAccel>> ReferenceBrickBuilder::build(BrickData&& brick) const {
  OUTCORE_ASSIGN_OR_RETURN(auto accel, ReferenceBrickAccel::build(std::move(brick)));
  return std::unique_ptr<BrickAccel>(std::move(accel));
}

const std::string& ReferenceBrickBuilder::name() const {
  static const std::string kName = "reference";
  return kName;
}

}  // namespace outcore
