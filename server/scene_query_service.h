// SceneQueryService: the gRPC service outcore.v1.SceneQuery, a thin layer over
// one QueryEngine. It checks each request (ray_batch.h), answers it with the
// engine, and turns the engine's Status into a grpc::Status in one place
// (grpc_status.h). F32X8 rays are traced in place in the request's bytes and
// hits are written straight into the reply's bytes.
//
// A unary request may instead carry a shared payload (shared_payload.h): its
// rays are copied out of the client's shared-memory object and its answers
// copied into it, accepted from loopback peers only.
//
// Deadlines and cancellation are checked before each batch is traced (unary)
// and between engine calls (streams); a batch already being traced runs to
// its end, unless the engine's cancellation stops it (the server's drain
// after SIGTERM, serve_command.h). Each stream chunk is answered by one
// reply, in order, echoing its sequence; the first bad chunk ends the stream
// with its error. A stream is read, traced and written by three threads
// (stream_pipeline.h), and chunks that queued up while the engine was busy
// are traced in one engine call.
//
// The handlers are here; the shared-memory call is in shared_memory_call.cpp,
// the streams in streamed_call.cpp, the wire's shapes in wire_mapping.h.
//
// Thread-safety: all handlers may run concurrently (gRPC's sync server calls
// them from its thread pool); counters are atomics (service_counters.h), the
// engine and the buffer pool are thread-safe.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "core/query/query_engine.h"
#include "core/ray/query_types.h"
#include "core/util/reuse_pool.h"
#include "outcore/v1/scene_query.grpc.pb.h"
#include "server/ray_batch.h"
#include "server/service_counters.h"
#include "server/shared_mapping_cache.h"
#include "server/stream_pipeline.h"

namespace outcore::server {

struct ServiceOptions {
  // Largest message either way, in bytes (the server's --max-message-mb);
  // a reply that would exceed it is refused up front as RESOURCE_EXHAUSTED.
  uint64_t max_message_bytes = uint64_t{64} << 20;
  // Most rays of a stream traced in one engine call: chunks that arrived
  // while the engine was busy are traced together up to this many (the
  // server's --stream-group-rays; see stream_pipeline.h). 0: automatic,
  // kGroupRaysPerBrick per brick of the store.
  uint64_t max_group_rays = 0;
  // How long a stream's tracer waits for the next chunk before tracing what
  // has arrived (stream_pipeline.h, "Gathering"; the server's
  // --stream-gather-ms). Negative: automatic, kGatherWaitOutOfCore when the
  // cache cannot hold the scene, else 0 (no waiting).
  int64_t gather_wait_ms = -1;
  // Accept SharedPayload requests from loopback peers (the server's
  // --no-shared-payloads turns this off).
  bool shared_payloads = true;
  // When not empty, every call must carry "authorization: Bearer <token>"
  // (the server's --auth-token-file; server_security.h).
  std::string auth_token;
};

// A call's ray and answer buffers (a shared-payload call's, a stream's
// groups') are kept for the next call when together they hold at most this
// many bytes (1 M rays take 64 MiB), so repeated batches do not fault fresh
// pages in; larger ones are freed. At most kKeptCallBuffers are kept.
inline constexpr std::size_t kKeptCallBuffers = 2;
inline constexpr uint64_t kKeepSharedBufferBytes = uint64_t{160} << 20;

// Under a tight budget a stream's chunks are gathered while they keep coming
// at most this far apart: well above the gap between loopback chunks, so a
// steady stream is gathered whole.
inline constexpr int64_t kGatherWaitOutOfCore = 50;

// The engine's cost per ray falls with the rays each brick gets per call,
// while on a scene of few bricks grouping only delays replies
// (docs/BENCHMARKS.md, "--stream-group-rays"). So streams are grouped up to
// this many rays per brick.
inline constexpr uint64_t kGroupRaysPerBrick = 1024;

// The unary calls are registered as gRPC's "streamed unary" methods: the
// handler reads the request itself, so bytes that do not parse are answered
// INVALID_ARGUMENT naming the message type (gRPC's generated handler answers
// them INTERNAL with no message). One message each way, as before. The
// streams' handlers are replaced likewise (constructor) to read bytes.
using SceneQueryBase = v1::SceneQuery::WithStreamedUnaryMethod_Intersect<
    v1::SceneQuery::WithStreamedUnaryMethod_Occluded<v1::SceneQuery::Service>>;

class SceneQueryService final : public SceneQueryBase {
 public:
  SceneQueryService(QueryEngine& engine, const ServiceOptions& options);

  grpc::Status StreamedIntersect(
      grpc::ServerContext* context,
      grpc::ServerUnaryStreamer<v1::QueryRequest, v1::IntersectResponse>* streamer) override;
  grpc::Status StreamedOccluded(
      grpc::ServerContext* context,
      grpc::ServerUnaryStreamer<v1::QueryRequest, v1::OccludedResponse>* streamer) override;

  grpc::Status Intersect(grpc::ServerContext* context, const v1::QueryRequest* request,
                         v1::IntersectResponse* response) override;
  grpc::Status Occluded(grpc::ServerContext* context, const v1::QueryRequest* request,
                        v1::OccludedResponse* response) override;
  grpc::Status GetSceneInfo(grpc::ServerContext* context, const v1::GetSceneInfoRequest* request,
                            v1::SceneInfo* response) override;
  grpc::Status GetStats(grpc::ServerContext* context, const v1::GetStatsRequest* request,
                        v1::ServerStats* response) override;
  // The dynamic layer (dynamic_calls.cpp).
  grpc::Status AddMesh(grpc::ServerContext* context, const v1::AddMeshRequest* request,
                       v1::AddMeshResponse* response) override;
  grpc::Status AddInstance(grpc::ServerContext* context, const v1::AddInstanceRequest* request,
                           v1::AddInstanceResponse* response) override;
  grpc::Status UpdateTransforms(grpc::ServerContext* context, const v1::UpdateTransformsRequest* request,
                                v1::DynamicVersion* response) override;
  grpc::Status UpdateVertices(grpc::ServerContext* context, const v1::UpdateVerticesRequest* request,
                              v1::DynamicVersion* response) override;
  grpc::Status Remove(grpc::ServerContext* context, const v1::RemoveRequest* request,
                      v1::DynamicVersion* response) override;
  // Every hit and point queries (every_hit_and_point_calls.cpp).
  grpc::Status CountIntersections(grpc::ServerContext* context, const v1::QueryRequest* request,
                                  v1::CountResponse* response) override;
  grpc::Status ListIntersections(grpc::ServerContext* context, const v1::QueryRequest* request,
                                 v1::ListResponse* response) override;
  grpc::Status QueryPoints(grpc::ServerContext* context, const v1::PointRequest* request,
                           v1::PointResponse* response) override;

  ServiceCounters counters() const;

  // Checks that the store on disk is still the one the engine opened (two
  // stat calls; the server's main loop calls it once a second). The first
  // time it is not (replaced by pack --force, or removed), logs a warning
  // naming it, and GetStats.store_changed says so from then on. The engine
  // goes on answering from the scene it opened, whole (scene_store.h).
  void check_store();

 private:
  // A shared-payload call's rays copied out of the client's object and its
  // answers before they are copied back; a stream group's gathered rays and
  // answers. Taken from call_buffers_ and given back when the lease ends.
  struct CallBuffers {
    std::vector<Ray> rays;
    std::vector<uint8_t> answers;  // operator new's alignment suits Hit
  };
  static bool worth_keeping(const CallBuffers& buffers);

  // The request's rays (in its bytes or widened into `storage`), or the
  // error naming what is wrong: layout, size, reply too large, bad rays.
  template <QueryKind kKind>
  Expected<std::span<const Ray>> check_request(const v1::QueryRequest& request, const BatchPosition& position,
                                               std::vector<Ray>& storage) const;
  // CANCELLED or DEADLINE_EXCEEDED naming `what` once the client no longer
  // waits for it.
  grpc::Status check_still_wanted(grpc::ServerContext* context, const std::string& what, uint64_t rays) const;
  // Answers `rays` into `out` (hit records or occlusion bytes) with the
  // request's flags and adds the engine's figures to the counters.
  template <QueryKind kKind>
  Status trace(std::span<const Ray> rays, uint8_t* out, const v1::QueryRequest& request,
               const std::shared_ptr<const DynamicSnapshot>& dynamic, QueryStats* stats);
  // The dynamic layer's version a call traces: the one the request names,
  // or the latest; held for all of the call's parts.
  Expected<std::shared_ptr<const DynamicSnapshot>> dynamic_for(const v1::QueryRequest& request) const;
  // The engine's options a request asks for, tracing the given version of
  // the dynamic layer.
  static QueryOptions options_of(const v1::QueryRequest& request,
                                 const std::shared_ptr<const DynamicSnapshot>& dynamic);
  // A call of the every-hit and point family: CANCELLED or DEADLINE_EXCEEDED
  // before `run` when the client no longer waits, then run's status,
  // counted and logged by finish() under `method`.
  template <class Run>
  grpc::Status answer_once_wanted(grpc::ServerContext* context, const char* method, uint64_t items,
                                  const Run& run);
  // Every hit of a request's rays: counts, and the sorted records when
  // `records` is given; checks the request as check_request does.
  Status every_hit(const v1::QueryRequest& request, std::vector<uint32_t>& counts,
                   std::vector<RayHitRecord>* records, QueryStats& stats);
  template <QueryKind kKind, class Response>
  grpc::Status answer(grpc::ServerContext* context, const v1::QueryRequest& request, Response* response);
  // answer() for a request with a shared payload (shared_payload.h).
  template <QueryKind kKind, class Response>
  grpc::Status answer_shared(grpc::ServerContext* context, const v1::QueryRequest& request,
                             Response* response);
  // The object a shared call names, checked (open_shared_payload), into
  // `object`; or why not: FAILED_PRECONDITION with the refusal marker when
  // the client should send bytes (--no-shared-payloads, not loopback, no
  // such object of its user), another code naming what is malformed.
  grpc::Status open_shared_call(grpc::ServerContext* context, const v1::QueryRequest& request,
                                uint64_t answer_bytes_per_ray, uint64_t answers_room,
                                std::shared_ptr<SharedMemoryObject>& object);
  // ListIntersections with a shared payload: the counts and hits written
  // into the object when they fit in shared.answers_bytes, else into the
  // reply as without one.
  grpc::Status answer_shared_list(grpc::ServerContext* context, const v1::QueryRequest& request,
                                  v1::ListResponse* response);
  // A ListResponse's counts and hits fields; RESOURCE_EXHAUSTED when they
  // would exceed the max message size.
  Status pack_list_reply(std::span<const uint32_t> counts, const std::vector<RayHitRecord>& records,
                         v1::ListResponse* response) const;
  // Answers a stream's group of chunks with one engine call, one reply each
  // (`buffers` gathers a group of several chunks; unused for one).
  template <QueryKind kKind, class Response>
  grpc::Status answer_group(grpc::ServerContext* context, std::span<const std::unique_ptr<StreamChunk>> group,
                            CallBuffers* buffers, std::span<const std::unique_ptr<Response>> replies);
  // What every chunk of a stream must share with its first: the hit fields
  // and the dynamic layer's version (taken at the first chunk).
  struct StreamSettings {
    v1::HitFields hit_fields = v1::HIT_FIELDS_ALL;
    std::shared_ptr<const DynamicSnapshot> dynamic;
    std::vector<uint32_t> only_bricks;  // the first chunk's, which every chunk repeats
  };
  // Takes the first chunk's settings into `stream`, or checks a later
  // chunk's against them (INVALID_ARGUMENT naming the chunk; NOT_FOUND for a
  // dynamic version no longer kept).
  Status settle_stream_chunk(const v1::QueryRequest& request, const BatchPosition& position,
                             StreamSettings& stream) const;
  // IntersectStream / OccludedStream. Chunks arrive as bytes and are parsed
  // here: gRPC's typed Read() reports bytes that do not parse as the end of
  // the stream, which would end it OK with the chunk unanswered.
  template <QueryKind kKind, class Response>
  grpc::Status serve_stream(grpc::ServerContext* context,
                            grpc::ServerReaderWriter<Response, grpc::ByteBuffer>* stream);
  // Reads a unary call's request (INVALID_ARGUMENT when its bytes do not
  // parse), answers it with `handler` and writes the reply.
  template <class Response, class Handler>
  grpc::Status serve_unary(grpc::ServerContext* context,
                           grpc::ServerUnaryStreamer<v1::QueryRequest, Response>* streamer,
                           const char* method, const Handler& handler);
  // UNAUTHENTICATED unless the call carries the token options_ require
  // (each handler's first step; health and reflection are not ours).
  grpc::Status authorize(const grpc::ServerContext& context) const;
  // Counts one answered request and logs it at debug level.
  grpc::Status finish(grpc::ServerContext* context, const char* method, const grpc::Status& status,
                      uint64_t rays, std::chrono::steady_clock::time_point start);

  QueryEngine& engine_;
  const ServiceOptions options_;  // max_group_rays resolved (never 0)
  AtomicServiceCounters counters_;
  // Spare CallBuffers (kKeptCallBuffers, kKeepSharedBufferBytes).
  ReusePool<CallBuffers> call_buffers_{kKeptCallBuffers, &SceneQueryService::worth_keeping};
  std::mutex store_changed_mutex_;
  std::string store_changed_;  // empty while the store on disk is the one opened
  // Client objects of recent shared calls, kept mapped (shared_mapping_cache.h).
  SharedMappingCache shared_mappings_;
};

}  // namespace outcore::server
