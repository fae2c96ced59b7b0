// Closest-hit records on the wire for the fields a request asks for
// (scene_query.proto, HitFields): the server packs them, the C++ client
// unpacks them into Hit. t, geometry_id and primitive_id lead outcore::Hit,
// so each packed record is its Hit's first bytes.
//
// Thread-safety: pure functions.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>

#include "core/ray/ray_types.h"
#include "outcore/v1/scene_query.pb.h"

namespace outcore::wire {

static_assert(offsetof(Hit, t) == 0 && offsetof(Hit, geometry_id) == 4 && offsetof(Hit, primitive_id) == 8);

// Bytes of one record; 0 for a value the proto does not define.
inline uint32_t hit_record_bytes(v1::HitFields fields) {
  switch (fields) {
    case v1::HIT_FIELDS_ALL: return sizeof(Hit);
    case v1::HIT_FIELDS_T: return sizeof(float);
    case v1::HIT_FIELDS_T_IDS: return sizeof(float) + 2 * sizeof(uint32_t);
    default: return 0;
  }
}

// Writes the fields of each hit, packed, at `out` (hits.size() * record bytes).
inline void pack_hit_fields(std::span<const Hit> hits, v1::HitFields fields, uint8_t* out) {
  const uint32_t bytes = hit_record_bytes(fields);
  if (bytes == sizeof(Hit)) {
    if (!hits.empty()) std::memcpy(out, static_cast<const void*>(hits.data()), hits.size_bytes());
    return;
  }
  for (std::size_t i = 0; i < hits.size(); ++i) std::memcpy(out + i * bytes, &hits[i], bytes);
}

// The inverse: hits[i] gets record i's fields, the others a miss's defaults
// (ids kInvalidId, u = v = 0, zero normal).
inline void unpack_hit_fields(const uint8_t* records, v1::HitFields fields, std::span<Hit> hits) {
  const uint32_t bytes = hit_record_bytes(fields);
  if (bytes == sizeof(Hit)) {
    if (!hits.empty()) std::memcpy(static_cast<void*>(hits.data()), records, hits.size_bytes());
    return;
  }
  for (std::size_t i = 0; i < hits.size(); ++i) {
    Hit hit;
    std::memcpy(static_cast<void*>(&hit), records + i * bytes, bytes);
    hits[i] = hit;
  }
}

}  // namespace outcore::wire
