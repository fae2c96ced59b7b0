#include "core/accel/reference_brick.h"

#include <chrono>
#include <cstdint>
#include <string>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/bvh/double_triangle_test.h"
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
  accel->normals_.reserve(brick.triangles.size());
  for (const Triangle& tri : brick.triangles) {
    const Vec3d v0(tri.v0), v1(tri.v1), v2(tri.v2);
    accel->normals_.push_back(Vec3f(normalize(cross(v1 - v0, v2 - v0))));
  }
  accel->triangles_ = std::move(brick.triangles);
  accel->ids_ = std::move(brick.ids);
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

uint64_t ReferenceBrickAccel::memory_bytes() const {
  return kOverheadBytes + triangles_.capacity() * sizeof(Triangle) + ids_.capacity() * sizeof(TriangleId) +
         normals_.capacity() * sizeof(Vec3f);
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
      if (!hit_is_better(h.t, ids_[k].geometry_id, ids_[k].primitive_id, best)) continue;
      best.t = h.t;
      best.geometry_id = ids_[k].geometry_id;
      best.primitive_id = ids_[k].primitive_id;
      found = k;
      found_hit = h;
    }
    if (found == kInvalidId) continue;
    best.u = found_hit.u;
    best.v = found_hit.v;
    best.normal = normals_[found];
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

Expected<std::unique_ptr<BrickAccel>> ReferenceBrickBuilder::build(BrickData&& brick) const {
  OUTCORE_ASSIGN_OR_RETURN(auto accel, ReferenceBrickAccel::build(std::move(brick)));
  return std::unique_ptr<BrickAccel>(std::move(accel));
}

const std::string& ReferenceBrickBuilder::name() const {
  static const std::string kName = "reference";
  return kName;
}

}  // namespace outcore
