// Decoding and checking a wire RayBatch (layout version 1, see
// proto/outcore/v1/scene_query.proto) into the engine's rays, and naming rays
// in error messages by their place in the call.
//
// F32X8 is byte-identical to outcore::Ray, so its rays are used in place inside
// the request's bytes (no copy) whenever those bytes are float-aligned; F32X6
// rows are widened into caller-provided storage.
//
// Thread-safety: free functions, reentrant.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/util/status.h"
#include "outcore/v1/scene_query.pb.h"

namespace outcore::server {

// Where a batch sits in its call: a unary call is one batch (a shared one
// may be traced in groups, each starting at `first_ray`); a stream's chunk
// `chunk` (0-based, in arrival order) starts at global ray `first_ray`.
struct BatchPosition {
  bool streamed = false;
  uint64_t chunk = 0;
  uint64_t first_ray = 0;
};

// Bytes per ray of a layout, 0 for RAY_LAYOUT_UNSPECIFIED and unknown values.
uint32_t ray_layout_bytes(int layout);

// Checks layout_version and ray_layout (INVALID_ARGUMENT naming the field);
// the layout's bytes per ray.
Expected<uint32_t> check_batch_layout(const v1::RayBatch& batch);

// Widens `count` F32X6 rows (24 bytes each, any alignment) into rays with
// tnear = 0 and tfar = +inf.
void widen_f32x6(const char* rows, uint64_t count, Ray* out);

// Checks layout_version, ray_layout, that rays is a whole number of rays and
// that ray_count agrees; INVALID_ARGUMENT naming the field otherwise. The rays
// returned live in batch.rays() or in `storage`.
Expected<std::span<const Ray>> decode_ray_batch(const v1::RayBatch& batch, std::vector<Ray>& storage);

// "ray 7" in a unary call; "ray 1007 (chunk 2, ray 7 of the chunk)" in a stream:
// the first number is always the ray's index in everything the call sent.
std::string ray_name(const BatchPosition& position, uint64_t index_in_batch);

// With `strict`, INVALID_ARGUMENT naming the first invalid ray (ray_name,
// ray_problem) by its place in the call; otherwise OK (the engine answers
// invalid rays, components beyond Embree's range included, as counted misses).
Status check_rays(std::span<const Ray> rays, const BatchPosition& position, bool strict);

}  // namespace outcore::server
