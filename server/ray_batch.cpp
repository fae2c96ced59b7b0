#include "server/ray_batch.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/query/query_engine.h"

namespace outcore::server {

static_assert(std::endian::native == std::endian::little, "the wire layouts are little-endian");
static_assert(sizeof(Ray) == 32 && alignof(Ray) == alignof(float), "F32X8 is read in place as outcore::Ray");

uint32_t ray_layout_bytes(int layout) {
  switch (layout) {
    case v1::RAY_LAYOUT_F32X8: return 32;
    case v1::RAY_LAYOUT_F32X6: return 24;
    default: return 0;
  }
}

Expected<uint32_t> check_batch_layout(const v1::RayBatch& batch) {
  if (batch.layout_version() != 1) {
    return invalid_argument("batch.layout_version is " + std::to_string(batch.layout_version()) +
                            "; this server reads layout version 1");
  }
  const uint32_t ray_bytes = ray_layout_bytes(batch.ray_layout());
  if (ray_bytes == 0) {
    return invalid_argument("batch.ray_layout is " +
                            (batch.ray_layout() == v1::RAY_LAYOUT_UNSPECIFIED
                                 ? std::string("RAY_LAYOUT_UNSPECIFIED")
                                 : "the unknown value " + std::to_string(batch.ray_layout())) +
                            "; use RAY_LAYOUT_F32X8 or RAY_LAYOUT_F32X6");
  }
  return ray_bytes;
}

void widen_f32x6(const char* rows, uint64_t count, Ray* out) {
  for (uint64_t i = 0; i < count; ++i) {
    float row[6];
    std::memcpy(row, rows + i * 24, sizeof row);
    Ray& ray = out[i];
    ray.origin = Vec3f(row[0], row[1], row[2]);
    ray.direction = Vec3f(row[3], row[4], row[5]);
    ray.tnear = 0.0f;
    ray.tfar = std::numeric_limits<float>::infinity();
  }
}

Expected<std::span<const Ray>> decode_ray_batch(const v1::RayBatch& batch, std::vector<Ray>& storage) {
  OUTCORE_ASSIGN_OR_RETURN(const uint32_t ray_bytes, check_batch_layout(batch));
  const std::string& bytes = batch.rays();
  const char* layout_name = ray_bytes == 32 ? "RAY_LAYOUT_F32X8" : "RAY_LAYOUT_F32X6";
  if (bytes.size() % ray_bytes != 0) {
    return invalid_argument("batch.rays has " + std::to_string(bytes.size()) +
                            " bytes, not a whole number of " + std::to_string(ray_bytes) + "-byte rays (" +
                            layout_name + ")");
  }
  const uint64_t count = bytes.size() / ray_bytes;
  if (batch.ray_count() != count) {
    return invalid_argument("batch.ray_count is " + std::to_string(batch.ray_count()) +
                            " but batch.rays holds " + std::to_string(count) + " rays (" +
                            std::to_string(bytes.size()) + " bytes, " + layout_name + ")");
  }
  if (count == 0) return std::span<const Ray>();
  if (ray_bytes == 32) {
    // std::string storage comes from operator new or an arena (8-byte aligned)
    // in practice; the check keeps a misaligned buffer correct, only slower.
    if (reinterpret_cast<uintptr_t>(bytes.data()) % alignof(Ray) == 0) {
      return std::span<const Ray>(reinterpret_cast<const Ray*>(bytes.data()), count);
    }
    storage.resize(count);
    std::memcpy(static_cast<void*>(storage.data()), bytes.data(), bytes.size());
    return std::span<const Ray>(storage);
  }
  storage.resize(count);
  widen_f32x6(bytes.data(), count, storage.data());
  return std::span<const Ray>(storage);
}

std::string ray_name(const BatchPosition& position, uint64_t index_in_batch) {
  if (!position.streamed) return "ray " + std::to_string(position.first_ray + index_in_batch);
  return "ray " + std::to_string(position.first_ray + index_in_batch) + " (chunk " +
         std::to_string(position.chunk) + ", ray " + std::to_string(index_in_batch) + " of the chunk)";
}

Status check_rays(std::span<const Ray> rays, const BatchPosition& position, bool strict) {
  if (!strict) return Status::Ok();  // the engine answers invalid rays as counted misses
  for (size_t i = 0; i < rays.size(); ++i) {
    if (const char* problem = ray_problem(rays[i]))
      return invalid_argument(ray_name(position, i) + ": " + problem);
  }
  return Status::Ok();
}

}  // namespace outcore::server
