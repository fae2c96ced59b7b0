#include "core/accel/bvh/wide_bvh_trace.h"

#include <cstdlib>
#include <string>

namespace outcore {

std::string_view simd_path_name(SimdPath path) {
  return path == SimdPath::kAvx2 ? "avx2" : "sse4";
}

bool simd_path_supported(SimdPath path) {
#if defined(__x86_64__) || defined(__i386__)
  if (path == SimdPath::kSse4) return true;
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2;
#else
  (void)path;
  return false;
#endif
}

Expected<SimdPath> simd_path_from_environment() {
  const char* named = std::getenv("OUTCORE_SIMD");
  const SimdPath widest = simd_path_supported(SimdPath::kAvx2) ? SimdPath::kAvx2 : SimdPath::kSse4;
  if (named == nullptr || *named == '\0') return widest;
  const std::string name = named;
  for (const SimdPath path : {SimdPath::kSse4, SimdPath::kAvx2}) {
    if (name != simd_path_name(path)) continue;
    if (!simd_path_supported(path)) {
      return invalid_argument("OUTCORE_SIMD=" + name + ": this CPU does not support " + name);
    }
    return path;
  }
  return invalid_argument("OUTCORE_SIMD must be sse4 or avx2, got '" + name + "'");
}

SimdPath active_simd_path() {
  static const SimdPath path = [] {
    const Expected<SimdPath> chosen = simd_path_from_environment();
    if (chosen.ok()) return *chosen;
    return simd_path_supported(SimdPath::kAvx2) ? SimdPath::kAvx2 : SimdPath::kSse4;
  }();
  return path;
}

void wide_bvh_intersect(SimdPath path, TriangleTest test, const WideBvhView& tree,
                        std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) {
  if (tree.nodes.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::intersect(test, tree, ray_ids, rays, hits);
  wide_sse4::intersect(test, tree, ray_ids, rays, hits);
}

void wide_bvh_occluded(SimdPath path, TriangleTest test, const WideBvhView& tree,
                       std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) {
  if (tree.nodes.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::occluded(test, tree, ray_ids, rays, occluded);
  wide_sse4::occluded(test, tree, ray_ids, rays, occluded);
}

void wide_bvh_all_hits(SimdPath path, TriangleTest test, const WideBvhView& tree,
                       std::span<const uint32_t> ray_ids, const Ray* rays, std::vector<RayHitRecord>& out) {
  if (tree.nodes.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::all_hits(test, tree, ray_ids, rays, out);
  wide_sse4::all_hits(test, tree, ray_ids, rays, out);
}

void wide_bvh_count_hits(SimdPath path, TriangleTest test, const WideBvhView& tree,
                         std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts) {
  if (tree.nodes.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::count_hits(test, tree, ray_ids, rays, counts);
  wide_sse4::count_hits(test, tree, ray_ids, rays, counts);
}

void append_hit(std::vector<RayHitRecord>& out, uint32_t ray, const Hit& hit) {
  out.push_back({ray, hit});
}

void wide_bvh_set_intersect(SimdPath path, TriangleTest test, const WideBvhSetView& set,
                            std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) {
  if (set.trees.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::set_intersect(test, set, ray_ids, rays, hits);
  wide_sse4::set_intersect(test, set, ray_ids, rays, hits);
}

void wide_bvh_set_occluded(SimdPath path, TriangleTest test, const WideBvhSetView& set,
                           std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) {
  if (set.trees.empty()) return;
  if (path == SimdPath::kAvx2) return wide_avx2::set_occluded(test, set, ray_ids, rays, occluded);
  wide_sse4::set_occluded(test, set, ray_ids, rays, occluded);
}

}  // namespace outcore
