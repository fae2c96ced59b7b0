#include "core/accel/triangle_hit_records.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <cassert>
#include <string>

namespace outcore {

namespace {

#if defined(__SSE2__)
// Triangle::unit_normal of triangles k and k + 1 at once, one per lane of
// SSE2's float64 pairs: each lane takes the scalar code's IEEE operations in
// its order (square root and quotients are correctly rounded, no fused
// products), so the normals are bitwise the scalar ones. The square root
// and the three divisions were a tenth of a grid's build, one at a time.
void unit_normals_of_pair(const Triangle& p, const Triangle& q, Vec3f& np, Vec3f& nq) {
  const auto pair = [](float a, float b) { return _mm_set_pd(double{b}, double{a}); };
  const __m128d ax = pair(p.v0.x, q.v0.x), ay = pair(p.v0.y, q.v0.y), az = pair(p.v0.z, q.v0.z);
  const __m128d ex = _mm_sub_pd(pair(p.v1.x, q.v1.x), ax), ey = _mm_sub_pd(pair(p.v1.y, q.v1.y), ay),
                ez = _mm_sub_pd(pair(p.v1.z, q.v1.z), az);
  const __m128d fx = _mm_sub_pd(pair(p.v2.x, q.v2.x), ax), fy = _mm_sub_pd(pair(p.v2.y, q.v2.y), ay),
                fz = _mm_sub_pd(pair(p.v2.z, q.v2.z), az);
  const __m128d nx = _mm_sub_pd(_mm_mul_pd(ey, fz), _mm_mul_pd(ez, fy));
  const __m128d ny = _mm_sub_pd(_mm_mul_pd(ez, fx), _mm_mul_pd(ex, fz));
  const __m128d nz = _mm_sub_pd(_mm_mul_pd(ex, fy), _mm_mul_pd(ey, fx));
  const __m128d length =
      _mm_sqrt_pd(_mm_add_pd(_mm_add_pd(_mm_mul_pd(nx, nx), _mm_mul_pd(ny, ny)), _mm_mul_pd(nz, nz)));
  alignas(16) double x[2], y[2], z[2];
  _mm_store_pd(x, _mm_div_pd(nx, length));
  _mm_store_pd(y, _mm_div_pd(ny, length));
  _mm_store_pd(z, _mm_div_pd(nz, length));
  np = Vec3f(static_cast<float>(x[0]), static_cast<float>(y[0]), static_cast<float>(z[0]));
  nq = Vec3f(static_cast<float>(x[1]), static_cast<float>(y[1]), static_cast<float>(z[1]));
}
#endif

}  // namespace

std::vector<BvhHitRecord> hit_records_for(std::span<const Triangle> triangles,
                                          std::span<const TriangleId> ids) {
  assert(ids.size() == triangles.size());
  std::vector<BvhHitRecord> records(triangles.size());
  std::size_t k = 0;
#if defined(__SSE2__)
  for (; k + 1 < triangles.size(); k += 2) {
    unit_normals_of_pair(triangles[k], triangles[k + 1], records[k].normal, records[k + 1].normal);
  }
#endif
  for (; k < triangles.size(); ++k) records[k].normal = triangles[k].unit_normal();
  for (k = 0; k < triangles.size(); ++k) {
    records[k].geometry_id = ids[k].geometry_id;
    records[k].primitive_id = ids[k].primitive_id;
  }
  return records;
}

Status validate_triangle_refs(const std::string& what, std::span<const uint32_t> refs,
                              std::span<const Triangle> triangles, std::span<const BvhHitRecord> records) {
  if (records.size() != triangles.size()) {
    return invalid_argument(what + ": " + std::to_string(records.size()) + " hit records for " +
                            std::to_string(triangles.size()) + " triangles");
  }
  for (std::size_t k = 0; k < refs.size(); ++k) {
    if (refs[k] >= triangles.size()) {
      return invalid_argument(what + ": reference " + std::to_string(k) + " names triangle " +
                              std::to_string(refs[k]) + " of " + std::to_string(triangles.size()));
    }
  }
  return Status::Ok();
}

}  // namespace outcore
