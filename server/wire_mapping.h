// The server's mapping between its calls and the wire: what each kind of
// query's reply looks like (KindTraits), how a request is named in errors
// (where), a reply's header fields, the engine's figures on the wire
// (proto/outcore/v1/query_stats_wire.h, shared with the C++ client), and the
// server-wide sums in ServerStats. Status codes are not mapped here but in
// grpc_status.h, their one place.
//
// Thread-safety: functions of their arguments; no state.
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>

#include "core/accel/brick_queries.h"
#include "core/query/query_stats.h"
#include "core/ray/query_types.h"
#include "outcore/v1/scene_query.pb.h"
#include "proto/outcore/v1/hit_fields_wire.h"
#include "proto/outcore/v1/query_stats_wire.h"
#include "server/ray_batch.h"

namespace outcore::server {

// Room for a reply's fields other than its payload (counts, sequence, stats).
inline constexpr uint64_t kReplyOverheadBytes = 512;

template <QueryKind kKind>
struct KindTraits;
template <>
struct KindTraits<QueryKind::kClosestHit> {
  using Response = v1::IntersectResponse;
  static constexpr uint64_t kReplyBytesPerRay = sizeof(Hit);
  static constexpr const char* kUnary = "Intersect";
  static constexpr const char* kStream = "IntersectStream";
  static std::string* payload(v1::IntersectResponse* response) { return response->mutable_hits(); }
};
template <>
struct KindTraits<QueryKind::kAnyHit> {
  using Response = v1::OccludedResponse;
  static constexpr uint64_t kReplyBytesPerRay = 1;
  static constexpr const char* kUnary = "Occluded";
  static constexpr const char* kStream = "OccludedStream";
  static std::string* payload(v1::OccludedResponse* response) { return response->mutable_occluded(); }
};

// Every hit has no stream; its counts (CountIntersections) may come through
// a shared payload, 4 bytes a ray. check_request reads the reply's size per
// ray (the counts; a list's hits come on top and are checked once known,
// every_hit_and_point_calls.cpp).
template <>
struct KindTraits<QueryKind::kAllHits> {
  using Response = v1::CountResponse;
  static constexpr uint64_t kReplyBytesPerRay = sizeof(uint32_t);
};

// Bytes of one ray's answer in a reply to `request`.
template <QueryKind kKind>
uint64_t reply_bytes_per_ray(const v1::QueryRequest& request) {
  if constexpr (kKind == QueryKind::kClosestHit) {
    return wire::hit_record_bytes(request.hit_fields());
  } else {
    return KindTraits<kKind>::kReplyBytesPerRay;
  }
}

// A list's hits in the wire's layout: each record's 32-byte hit, in order,
// at `out` (room for records.size() of them).
inline void pack_hit_records(std::span<const RayHitRecord> records, char* out) {
  for (std::size_t k = 0; k < records.size(); ++k)
    std::memcpy(out + k * sizeof(Hit), &records[k].hit, sizeof(Hit));
}

// "request", or "chunk N" of a stream: how errors name a batch.
std::string where(const BatchPosition& position);

// A reply's fields besides its payload and figures.
template <class Response>
void set_reply_header(Response* reply, uint64_t ray_count, uint64_t sequence) {
  reply->set_layout_version(1);
  reply->set_ray_count(ray_count);
  reply->set_sequence(sequence);
}

// The figures OUTCORE_QUERY_STATS marks kYes in its server column, summed
// over the requests answered, into their ServerStats fields.
void set_answered_sums(const QueryStats& answered, v1::ServerStats* out);

}  // namespace outcore::server
