// The shared-memory unary call: a request whose rays are in the client's
// shared-memory object (shared_payload.h) is answered into that object, in
// groups of kSharedGroupRays through reused buffers, from loopback peers only.
// Intersect, Occluded and CountIntersections (4-byte counts) take it.
//
// Thread-safety: as the service's handlers (scene_query_service.h).
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <cstring>
#include <span>
#include <string>

#include "proto/outcore/v1/shared_payload_wire.h"
#include "server/grpc_status.h"
#include "server/scene_query_service.h"
#include "server/shared_payload.h"
#include "server/wire_mapping.h"

namespace outcore::server {

grpc::Status SceneQueryService::open_shared_call(grpc::ServerContext* context,
                                                 const v1::QueryRequest& request,
                                                 uint64_t answer_bytes_per_ray, uint64_t answers_room,
                                                 std::shared_ptr<SharedMemoryObject>& object) {
  const auto refuse = [&](const std::string& why) {
    // The marker tells clients "send bytes from now on" apart from a failed call.
    context->AddTrailingMetadata(wire::kSharedRefusedKey, wire::kSharedRefusedValue);
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, why + "; send the rays in batch.rays");
  };
  if (request.hit_fields() != v1::HIT_FIELDS_ALL) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "request: hit_fields applies to answers in the reply's bytes; a shared payload's "
                        "answers are whole hit records (leave it HIT_FIELDS_ALL)");
  }
  if (!options_.shared_payloads) return refuse("this server runs with --no-shared-payloads");
  if (!is_loopback_peer(context->peer())) {
    return refuse("shared payloads are accepted from loopback peers only, not from " + context->peer());
  }
  auto opened = open_shared_payload(request, answer_bytes_per_ray, shared_mappings_, answers_room);
  if (!opened.ok()) {
    if (opened.status().code() == StatusCode::kFailedPrecondition) return refuse(opened.status().message());
    return to_grpc_status(opened.status().with_context("request"));
  }
  object = std::move(*opened);
  return grpc::Status::OK;
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer_shared(grpc::ServerContext* context, const v1::QueryRequest& request,
                                              Response* response) {
  using Traits = KindTraits<kKind>;
  std::shared_ptr<SharedMemoryObject> object;
  OUTCORE_RETURN_IF_GRPC_ERROR(open_shared_call(context, request, Traits::kReplyBytesPerRay, 0, object));
  const uint64_t n = request.batch().ray_count();
  const ReusePool<CallBuffers>::Lease buffers = call_buffers_.take();
  v1::QueryStats* wire_stats = response->mutable_stats();
  auto dynamic = dynamic_for(request);
  if (!dynamic.ok()) return to_grpc_status(dynamic.status().with_context("request.dynamic_version"));
  // Groups in order, so under strict mode the first bad ray found is the
  // call's first (earlier groups had none). An empty batch is one empty group.
  const uint64_t groups = std::max<uint64_t>(1, (n + kSharedGroupRays - 1) / kSharedGroupRays);
  for (uint64_t group = 0; group < groups; ++group) {
    const uint64_t first = group * kSharedGroupRays;
    const uint64_t count = std::min(kSharedGroupRays, n - first);
    OUTCORE_RETURN_IF_GRPC_ERROR(check_still_wanted(context, "request", n - first));
    const Status read = read_shared_rays(*object, request, first, count, buffers->rays);
    if (!read.ok()) return to_grpc_status(read.with_context("request"));
    const std::span<const Ray> rays(buffers->rays.data(), count);
    BatchPosition position;
    position.first_ray = first;
    if (const Status bad = check_rays(rays, position, request.strict()); !bad.ok())
      return to_grpc_status(bad);
    const uint64_t answer_bytes = count * Traits::kReplyBytesPerRay;
    if (buffers->answers.size() < answer_bytes) buffers->answers.resize(answer_bytes);
    QueryStats stats;
    const Status status = trace<kKind>(rays, buffers->answers.data(), request, *dynamic, &stats);
    if (!status.ok()) return to_grpc_status(status);
    const Status written =
        write_shared_answers(*object, request.shared(), first * Traits::kReplyBytesPerRay,
                             std::span<const uint8_t>(buffers->answers.data(), answer_bytes));
    if (!written.ok()) return to_grpc_status(written.with_context("request"));
    wire::add_to_wire(stats, wire_stats);
  }
  if constexpr (kKind == QueryKind::kAllHits) {
    // Counts see the static scene only (the engine refuses a batch while
    // the dynamic layer holds instances): no version, and no sequence.
    response->set_layout_version(1);
    response->set_ray_count(n);
  } else {
    set_reply_header(response, n, request.sequence());
    response->set_dynamic_version((*dynamic)->version);
  }
  response->set_answers_in_shared(true);
  return grpc::Status::OK;
}

template grpc::Status SceneQueryService::answer_shared<QueryKind::kClosestHit, v1::IntersectResponse>(
    grpc::ServerContext*, const v1::QueryRequest&, v1::IntersectResponse*);
grpc::Status SceneQueryService::answer_shared_list(grpc::ServerContext* context,
                                                   const v1::QueryRequest& request,
                                                   v1::ListResponse* response) {
  const uint64_t n = request.batch().ray_count();
  if (n > kSharedGroupRays) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "request: a ListIntersections with a shared payload takes at most " +
                            std::to_string(kSharedGroupRays) + " rays, not " + std::to_string(n) +
                            "; send fewer rays per call");
  }
  const uint64_t room = request.shared().answers_bytes();
  if (room == 0) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "request: shared.answers_bytes is 0; a ListIntersections with a shared payload must "
                        "say how much room its answers have (at least 4 bytes a ray)");
  }
  std::shared_ptr<SharedMemoryObject> object;
  OUTCORE_RETURN_IF_GRPC_ERROR(open_shared_call(context, request, sizeof(uint32_t), room, object));
  OUTCORE_RETURN_IF_GRPC_ERROR(check_still_wanted(context, "request", n));
  const ReusePool<CallBuffers>::Lease buffers = call_buffers_.take();
  const auto run = [&]() -> Status {
    OUTCORE_RETURN_IF_ERROR(read_shared_rays(*object, request, 0, n, buffers->rays).with_context("request"));
    const std::span<const Ray> rays(buffers->rays.data(), n);
    OUTCORE_RETURN_IF_ERROR(check_rays(rays, BatchPosition{}, request.strict()));
    std::vector<uint32_t> counts(n, 0);
    std::vector<RayHitRecord> records;
    QueryStats stats;
    OUTCORE_ASSIGN_OR_RETURN(auto dynamic, dynamic_for(request));
    OUTCORE_RETURN_IF_ERROR(engine_.all_hits(rays, counts, &records, options_of(request, dynamic), &stats));
    counters_.add_answered(stats);
    wire::to_wire(stats, response->mutable_stats());
    response->set_layout_version(1);
    response->set_ray_count(n);
    response->set_hit_count(records.size());
    const uint64_t hits_bytes = records.size() * sizeof(Hit);
    if (n * sizeof(uint32_t) + hits_bytes > room) return pack_list_reply(counts, records, response);
    // Counts then hits, packed through the call's buffer (the copies into the
    // object are the SIGBUS-guarded ones).
    std::vector<uint8_t>& packed = buffers->answers;
    packed.resize(n * sizeof(uint32_t) + hits_bytes);
    if (n != 0) std::memcpy(packed.data(), counts.data(), n * sizeof(uint32_t));
    pack_hit_records(records, reinterpret_cast<char*>(packed.data()) + n * sizeof(uint32_t));
    OUTCORE_RETURN_IF_ERROR(
        write_shared_answers(*object, request.shared(), 0, packed).with_context("request"));
    response->set_answers_in_shared(true);
    return Status::Ok();
  };
  return to_grpc_status(run());
}

template grpc::Status SceneQueryService::answer_shared<QueryKind::kAnyHit, v1::OccludedResponse>(
    grpc::ServerContext*, const v1::QueryRequest&, v1::OccludedResponse*);
template grpc::Status SceneQueryService::answer_shared<QueryKind::kAllHits, v1::CountResponse>(
    grpc::ServerContext*, const v1::QueryRequest&, v1::CountResponse*);

}  // namespace outcore::server
