// The bytes path's messages without protobuf's copies: a QueryRequest is
// sent as a grpc::ByteBuffer whose rays slice points at the caller's rays
// (only the few header bytes are encoded), and a reply is kept as the
// ByteBuffer gRPC received, its answers copied once, straight from gRPC's
// slices into the caller's array. The typed messages (outcore.v1.QueryRequest
// and the responses) copy the rays into a string and that string into
// gRPC's slices, and the answers out of the slices into a string and from
// there into the caller's array: four passes over 56 MB for 1 M rays.
//
// The wire bytes are exactly the typed messages' (tests parse them back with
// the generated classes), so the server sees no difference.
//
// Thread-safety: values; the request's rays must stay alive and unchanged
// until its call has finished.
#pragma once

#include <grpcpp/impl/codegen/serialization_traits.h>
#include <grpcpp/support/byte_buffer.h>

#include <cstdint>
#include <span>
#include <string>

#include "core/ray/ray_types.h"
#include "core/util/status.h"
#include "outcore/v1/scene_query.pb.h"

namespace outcore::client {

// A serialized message as gRPC's slices, either way: a request encoded by
// encode_query_request, a reply as gRPC received it.
struct RawQueryMessage {
  grpc::ByteBuffer buffer;
};
using RawQueryRequest = RawQueryMessage;
using RawQueryReply = RawQueryMessage;

struct QueryRequestFields {
  bool strict = false;
  bool no_reorder = false;
  uint64_t sequence = 0;
  v1::HitFields hit_fields = v1::HIT_FIELDS_ALL;
  std::span<const uint32_t> only_bricks;  // packed field 8; empty: left out
};

// A QueryRequest of F32X8 `rays` (referenced, not copied).
RawQueryRequest encode_query_request(std::span<const Ray> rays, const QueryRequestFields& fields);

// An IntersectResponse's or OccludedResponse's fields besides its answers.
struct ReplyHeader {
  uint32_t layout_version = 0;
  uint64_t ray_count = 0;
  uint64_t sequence = 0;
  bool answers_in_shared = false;
  uint64_t dynamic_version = 0;
  uint64_t answer_bytes = 0;  // the size of field 3 (hits / occluded)
  v1::QueryStats stats;
};

// Parses `reply`, copying its answers (field 3) to `answers` when they are
// exactly answers.size() bytes (else header.answer_bytes says how many there
// were and nothing is copied). DATA_LOSS when the bytes do not parse.
Status decode_query_reply(const RawQueryReply& reply, std::span<uint8_t> answers, ReplyHeader& header);

}  // namespace outcore::client

namespace grpc {

template <>
class SerializationTraits<outcore::client::RawQueryMessage, void> {
 public:
  static Status Serialize(const outcore::client::RawQueryMessage& message, ByteBuffer* buffer,
                          bool* own_buffer) {
    *buffer = message.buffer;  // the slices are shared, not copied
    *own_buffer = true;
    return Status::OK;
  }
  static Status Deserialize(ByteBuffer* buffer, outcore::client::RawQueryMessage* message) {
    message->buffer.Swap(buffer);
    buffer->Clear();
    return Status::OK;
  }
};

}  // namespace grpc
