#include "server/scene_query_service.h"

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/method_handler.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "proto/outcore/v1/query_stats_fields.h"
#include "proto/outcore/v1/shared_payload_wire.h"
#include "server/grpc_status.h"
#include "server/shared_payload.h"
#include "server/stream_pipeline.h"

namespace outcore::server {

namespace {

using Clock = std::chrono::steady_clock;

// Room for a reply's fields other than its payload (counts, sequence, stats).
constexpr uint64_t kReplyOverheadBytes = 512;

template <QueryKind kKind>
struct KindTraits;
template <>
struct KindTraits<QueryKind::kClosestHit> {
  static constexpr uint64_t kReplyBytesPerRay = sizeof(Hit);
  static constexpr const char* kUnary = "Intersect";
  static constexpr const char* kStream = "IntersectStream";
  static std::string* payload(v1::IntersectResponse* response) { return response->mutable_hits(); }
};
template <>
struct KindTraits<QueryKind::kAnyHit> {
  static constexpr uint64_t kReplyBytesPerRay = 1;
  static constexpr const char* kUnary = "Occluded";
  static constexpr const char* kStream = "OccludedStream";
  static std::string* payload(v1::OccludedResponse* response) { return response->mutable_occluded(); }
};

std::string where(const BatchPosition& position) {
  return position.streamed ? "chunk " + std::to_string(position.chunk) : std::string("request");
}

// The one conversion of the engine's figures into the wire's.
void fill_stats(const QueryStats& stats, v1::QueryStats* out) {
#define OUTCORE_SET_WIRE_FIELD(name) out->set_##name(stats.name);
  OUTCORE_WIRE_QUERY_STATS(OUTCORE_SET_WIRE_FIELD)
#undef OUTCORE_SET_WIRE_FIELD
}

// Adds the engine's figures to the wire's (a shared call traced in groups).
void add_stats(const QueryStats& stats, v1::QueryStats* out) {
#define OUTCORE_ADD_WIRE_FIELD(name) out->set_##name(out->name() + stats.name);
  OUTCORE_WIRE_QUERY_STATS(OUTCORE_ADD_WIRE_FIELD)
#undef OUTCORE_ADD_WIRE_FIELD
}

#define OUTCORE_RETURN_IF_GRPC_ERROR(expr) \
  do {                                     \
    const grpc::Status _status = (expr);   \
    if (!_status.ok()) return _status;     \
  } while (false)

bool deadline_passed(const grpc::ServerContext* context) {
  return context->deadline() <= std::chrono::system_clock::now();
}

}  // namespace

namespace {

ServiceOptions resolve(const ServiceOptions& options, const QueryEngine& engine) {
  ServiceOptions resolved = options;
  if (resolved.max_group_rays == 0) {
    resolved.max_group_rays = std::max<uint64_t>(1, kGroupRaysPerBrick * engine.store().brick_count());
  }
  if (resolved.gather_wait_ms < 0)
    resolved.gather_wait_ms = engine.cache_fits_scene() ? 0 : kGatherWaitOutOfCore;
  return resolved;
}

}  // namespace

SceneQueryService::SceneQueryService(QueryEngine& engine, const ServiceOptions& options)
    : engine_(engine), options_(resolve(options, engine)) {
  // The streams' handlers read bytes (serve_stream). Methods are numbered in
  // the order of scene_query.proto's service block, as the generated code's
  // WithStreamedUnaryMethod_* number Intersect 0 and Occluded 1.
  constexpr int kIntersectStreamMethod = 2;
  constexpr int kOccludedStreamMethod = 3;
  MarkMethodStreamed(
      kIntersectStreamMethod,
      new grpc::internal::BidiStreamingHandler<SceneQueryService, grpc::ByteBuffer, v1::IntersectResponse>(
          [](SceneQueryService* service, grpc::ServerContext* context,
             grpc::ServerReaderWriter<v1::IntersectResponse, grpc::ByteBuffer>* stream) {
            return service->serve_stream<QueryKind::kClosestHit>(context, stream);
          },
          this));
  MarkMethodStreamed(
      kOccludedStreamMethod,
      new grpc::internal::BidiStreamingHandler<SceneQueryService, grpc::ByteBuffer, v1::OccludedResponse>(
          [](SceneQueryService* service, grpc::ServerContext* context,
             grpc::ServerReaderWriter<v1::OccludedResponse, grpc::ByteBuffer>* stream) {
            return service->serve_stream<QueryKind::kAnyHit>(context, stream);
          },
          this));
  spdlog::debug("streams: chunks traced together up to {} rays, gathered while at most {} ms apart",
                options_.max_group_rays, options_.gather_wait_ms);
}

template <QueryKind kKind>
Expected<std::span<const Ray>> SceneQueryService::check_request(const v1::QueryRequest& request,
                                                                const BatchPosition& position,
                                                                std::vector<Ray>& storage) const {
  if (request.has_shared()) {
    return invalid_argument(where(position) +
                            ": shared payloads are for the unary calls (Intersect, Occluded), not streams");
  }
  auto rays = decode_ray_batch(request.batch(), storage);
  if (!rays.ok()) return rays.status().with_context(where(position));
  const uint64_t n = rays->size();
  const uint64_t reply_bytes = n * KindTraits<kKind>::kReplyBytesPerRay + kReplyOverheadBytes;
  if (reply_bytes > options_.max_message_bytes) {
    return resource_exhausted(where(position) + ": the reply to " + std::to_string(n) +
                              " rays would take about " + std::to_string(reply_bytes) +
                              " bytes, over the server's max message size of " +
                              std::to_string(options_.max_message_bytes) +
                              " bytes (--max-message-mb); send fewer rays per message");
  }
  OUTCORE_RETURN_IF_ERROR(check_rays(*rays, position, request.strict()));
  return rays;
}

grpc::Status SceneQueryService::check_still_wanted(grpc::ServerContext* context, const std::string& what,
                                                   uint64_t rays) const {
  if (context->IsCancelled()) {
    return grpc::Status(grpc::StatusCode::CANCELLED, what + " cancelled by the client before tracing");
  }
  if (deadline_passed(context)) {
    return grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, "the deadline expired before " + what + " (" +
                                                                 std::to_string(rays) + " rays) was traced");
  }
  return grpc::Status::OK;
}

template <QueryKind kKind>
Status SceneQueryService::trace(std::span<const Ray> rays, uint8_t* out, const v1::QueryRequest& request,
                                QueryStats* stats) {
  QueryOptions query_options;
  query_options.reorder = !request.no_reorder();
  query_options.strict = request.strict();
  const uint64_t n = rays.size();
  Status status;
  if constexpr (kKind == QueryKind::kClosestHit) {
    // Hits go straight into `out` (a reply's bytes); a std::string's buffer
    // is float-aligned in practice, the fallback only costs a copy.
    if (reinterpret_cast<uintptr_t>(out) % alignof(Hit) == 0) {
      status = engine_.intersect(rays, std::span<Hit>(reinterpret_cast<Hit*>(out), n), query_options, stats);
    } else {
      std::vector<Hit> hits(n);
      status = engine_.intersect(rays, hits, query_options, stats);
      if (n) std::memcpy(out, static_cast<const void*>(hits.data()), n * sizeof(Hit));
    }
  } else {
    status = engine_.occluded(rays, std::span<uint8_t>(out, n), query_options, stats);
  }
  if (status.ok()) {
    rays_.fetch_add(stats->rays, std::memory_order_relaxed);
    rays_hit_.fetch_add(stats->rays_hit, std::memory_order_relaxed);
    invalid_rays_.fetch_add(stats->invalid_rays, std::memory_order_relaxed);
    nanoseconds_tracing_.fetch_add(static_cast<uint64_t>(stats->seconds_total * 1e9),
                                   std::memory_order_relaxed);
    brick_visits_.fetch_add(stats->brick_visits, std::memory_order_relaxed);
    proxy_tests_.fetch_add(stats->proxy_tests, std::memory_order_relaxed);
    bricks_skipped_by_proxy_.fetch_add(stats->bricks_skipped_by_proxy, std::memory_order_relaxed);
    rays_traced_ahead_.fetch_add(stats->rays_traced_ahead, std::memory_order_relaxed);
    rays_in_brick_set_.fetch_add(stats->rays_in_brick_set, std::memory_order_relaxed);
  }
  return status;
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer(grpc::ServerContext* context, const v1::QueryRequest& request,
                                       Response* response) {
  using Traits = KindTraits<kKind>;
  if (request.has_shared()) return answer_shared<kKind>(context, request, response);
  const BatchPosition position;
  std::vector<Ray> widened;
  auto rays = check_request<kKind>(request, position, widened);
  if (!rays.ok()) return to_grpc_status(rays.status());
  const uint64_t n = rays->size();
  OUTCORE_RETURN_IF_GRPC_ERROR(check_still_wanted(context, where(position), n));
  std::string* payload = Traits::payload(response);
  payload->resize(n * Traits::kReplyBytesPerRay);
  QueryStats stats;
  const Status status = trace<kKind>(*rays, reinterpret_cast<uint8_t*>(payload->data()), request, &stats);
  if (!status.ok()) {
    payload->clear();
    return to_grpc_status(status);
  }
  response->set_layout_version(1);
  response->set_ray_count(n);
  response->set_sequence(request.sequence());
  fill_stats(stats, response->mutable_stats());
  return grpc::Status::OK;
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer_shared(grpc::ServerContext* context, const v1::QueryRequest& request,
                                              Response* response) {
  using Traits = KindTraits<kKind>;
  const auto refuse = [&](const std::string& why) {
    // The marker tells clients "send bytes from now on" apart from a failed call.
    context->AddTrailingMetadata(wire::kSharedRefusedKey, wire::kSharedRefusedValue);
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, why + "; send the rays in batch.rays");
  };
  if (!options_.shared_payloads) return refuse("this server runs with --no-shared-payloads");
  if (!is_loopback_peer(context->peer())) {
    return refuse("shared payloads are accepted from loopback peers only, not from " + context->peer());
  }
  auto object = open_shared_payload(request, Traits::kReplyBytesPerRay, shared_mappings_);
  if (!object.ok()) {
    if (object.status().code() == StatusCode::kFailedPrecondition) return refuse(object.status().message());
    return to_grpc_status(object.status().with_context("request"));
  }
  const uint64_t n = request.batch().ray_count();
  const SharedBuffersLease buffers = take_shared_buffers();
  v1::QueryStats* wire_stats = response->mutable_stats();
  // Groups in order, so under strict mode the first bad ray found is the
  // call's first (earlier groups had none). An empty batch is one empty group.
  const uint64_t groups = std::max<uint64_t>(1, (n + kSharedGroupRays - 1) / kSharedGroupRays);
  for (uint64_t group = 0; group < groups; ++group) {
    const uint64_t first = group * kSharedGroupRays;
    const uint64_t count = std::min(kSharedGroupRays, n - first);
    OUTCORE_RETURN_IF_GRPC_ERROR(check_still_wanted(context, "request", n - first));
    const Status read = read_shared_rays(**object, request, first, count, buffers->rays);
    if (!read.ok()) return to_grpc_status(read.with_context("request"));
    const std::span<const Ray> rays(buffers->rays.data(), count);
    BatchPosition position;
    position.first_ray = first;
    if (const Status bad = check_rays(rays, position, request.strict()); !bad.ok())
      return to_grpc_status(bad);
    const uint64_t answer_bytes = count * Traits::kReplyBytesPerRay;
    if (buffers->answers.size() < answer_bytes) buffers->answers.resize(answer_bytes);
    QueryStats stats;
    const Status status = trace<kKind>(rays, buffers->answers.data(), request, &stats);
    if (!status.ok()) return to_grpc_status(status);
    const Status written =
        write_shared_answers(**object, request.shared(), first * Traits::kReplyBytesPerRay,
                             std::span<const uint8_t>(buffers->answers.data(), answer_bytes));
    if (!written.ok()) return to_grpc_status(written.with_context("request"));
    add_stats(stats, wire_stats);
  }
  response->set_layout_version(1);
  response->set_ray_count(n);
  response->set_sequence(request.sequence());
  response->set_answers_in_shared(true);
  return grpc::Status::OK;
}

SceneQueryService::SharedBuffersLease SceneQueryService::take_shared_buffers() {
  std::unique_ptr<SharedBuffers> buffers;
  {
    std::lock_guard lock(shared_buffers_mutex_);
    if (!spare_shared_buffers_.empty()) {
      buffers = std::move(spare_shared_buffers_.back());
      spare_shared_buffers_.pop_back();
    }
  }
  if (buffers == nullptr) buffers = std::make_unique<SharedBuffers>();
  return SharedBuffersLease(buffers.release(), SharedBuffersReturn{this});
}

void SceneQueryService::SharedBuffersReturn::operator()(SharedBuffers* returned) const {
  std::unique_ptr<SharedBuffers> buffers(returned);
  const uint64_t bytes = buffers->rays.capacity() * sizeof(Ray) + buffers->answers.capacity();
  if (bytes > kKeepSharedBufferBytes) return;
  std::lock_guard lock(service->shared_buffers_mutex_);
  if (service->spare_shared_buffers_.size() < 2) service->spare_shared_buffers_.push_back(std::move(buffers));
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer_group(grpc::ServerContext* context,
                                             std::span<const std::unique_ptr<StreamChunk>> group,
                                             GroupBuffers& buffers,
                                             std::span<const std::unique_ptr<Response>> replies) {
  using Traits = KindTraits<kKind>;
  uint64_t n = 0;
  for (const auto& chunk : group) n += chunk->rays.size();
  const StreamChunk& first = *group.front();
  OUTCORE_RETURN_IF_GRPC_ERROR(
      check_still_wanted(context,
                         group.size() == 1 ? where(first.position)
                                           : "chunks " + std::to_string(first.position.chunk) + " to " +
                                                 std::to_string(group.back()->position.chunk),
                         n));

  QueryStats stats;
  Status status;
  if (group.size() == 1) {
    std::string* payload = Traits::payload(replies.front().get());
    payload->resize(n * Traits::kReplyBytesPerRay);
    status = trace<kKind>(first.rays, reinterpret_cast<uint8_t*>(payload->data()), first.request, &stats);
  } else {
    // One engine call for the whole group: its rays gathered into one batch,
    // its answers split into the chunks' replies (two copies, far cheaper
    // than tracing the chunks one by one; see stream_pipeline.h).
    buffers.rays.resize(n);
    buffers.answers.resize(n * Traits::kReplyBytesPerRay);
    uint64_t at = 0;
    for (const auto& chunk : group) {
      if (!chunk->rays.empty()) std::memcpy(&buffers.rays[at], chunk->rays.data(), chunk->rays.size_bytes());
      at += chunk->rays.size();
    }
    status =
        trace<kKind>(buffers.rays, reinterpret_cast<uint8_t*>(buffers.answers.data()), first.request, &stats);
    if (status.ok()) {
      at = 0;
      for (size_t i = 0; i < group.size(); ++i) {
        const uint64_t bytes = group[i]->rays.size() * Traits::kReplyBytesPerRay;
        Traits::payload(replies[i].get())
            ->assign(reinterpret_cast<const char*>(buffers.answers.data()) + at, bytes);
        at += bytes;
      }
    }
  }
  if (!status.ok()) return to_grpc_status(status.with_context(where(first.position)));
  for (size_t i = 0; i < group.size(); ++i) {
    Response* reply = replies[i].get();
    reply->set_layout_version(1);
    reply->set_ray_count(group[i]->rays.size());
    reply->set_sequence(group[i]->request.sequence());
    if (i + 1 == group.size()) {
      // The engine call's figures go with the group's last reply; the others
      // count only their own rays (the stream's sums stay exact).
      fill_stats(stats, reply->mutable_stats());
      reply->mutable_stats()->set_rays(group[i]->rays.size());
    } else {
      reply->mutable_stats()->set_rays(group[i]->rays.size());
    }
  }
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::finish(grpc::ServerContext* context, const char* method,
                                       const grpc::Status& status, uint64_t rays, Clock::time_point start) {
  requests_.fetch_add(1, std::memory_order_relaxed);
  // An answer the client no longer waits for (it cancelled, or the server's
  // drain cancelled the call) was never delivered: it is no success.
  const bool cancelled = status.error_code() == grpc::StatusCode::CANCELLED || context->IsCancelled();
  if (!status.ok() || cancelled) failed_requests_.fetch_add(1, std::memory_order_relaxed);
  if (cancelled) cancelled_requests_.fetch_add(1, std::memory_order_relaxed);
  if (spdlog::should_log(spdlog::level::debug)) {
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    if (status.ok()) {
      spdlog::debug("{}: {} rays in {:.3f} ms", method, rays, ms);
    } else {
      spdlog::debug("{}: {} rays refused in {:.3f} ms: code {}: {}", method, rays, ms,
                    static_cast<int>(status.error_code()), status.error_message());
    }
  }
  return status;
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::serve_stream(grpc::ServerContext* context,
                                             grpc::ServerReaderWriter<Response, grpc::ByteBuffer>* stream) {
  using Traits = KindTraits<kKind>;
  const auto stream_start = Clock::now();
  StreamPipeline<Response, grpc::ServerReaderWriter<Response, grpc::ByteBuffer>> pipeline(
      stream, options_.max_group_rays, std::chrono::milliseconds(options_.gather_wait_ms));
  // The tracer's first error; read once the tracer has been joined.
  grpc::Status tracer_status = grpc::Status::OK;
  pipeline.start([&] {
    typename StreamPipeline<Response>::Chunks group;
    typename StreamPipeline<Response>::Replies replies;
    GroupBuffers buffers;
    while (pipeline.take_group(group)) {
      const auto start = Clock::now();
      if (!pipeline.acquire_replies(group.size(), replies)) break;
      const grpc::Status status = answer_group<kKind, Response>(context, group, buffers, replies);
      for (const auto& chunk : group) {
        finish(context, Traits::kStream, status, chunk->rays.size(), start);
      }
      if (!status.ok()) {
        tracer_status = status;
        pipeline.fail();
        break;
      }
      pipeline.post_replies(replies, std::chrono::duration<double>(Clock::now() - start).count());
      pipeline.recycle(group);
    }
  });

  BatchPosition position;
  position.streamed = true;
  grpc::Status status = grpc::Status::OK;
  grpc::ByteBuffer bytes;
  for (;;) {
    std::unique_ptr<StreamChunk> chunk = pipeline.spare_chunk();
    const auto start = Clock::now();
    if (!stream->Read(&bytes)) break;
    if (!grpc::SerializationTraits<v1::QueryRequest>::Deserialize(&bytes, &chunk->request).ok()) {
      status = finish(
          context, Traits::kStream,
          grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, where(position) + " could not be parsed as " +
                                                               v1::QueryRequest::descriptor()->full_name() +
                                                               " (malformed protobuf bytes)"),
          0, start);
      break;
    }
    pipeline.add_reading_time(std::chrono::duration<double>(Clock::now() - start).count());
    chunk->position = position;
    auto rays = check_request<kKind>(chunk->request, position, chunk->widened);
    if (!rays.ok()) {
      status = finish(context, Traits::kStream, to_grpc_status(rays.status()),
                      chunk->request.batch().ray_count(), start);
      break;
    }
    chunk->rays = *rays;
    position.first_ray += rays->size();
    ++position.chunk;
    if (!pipeline.push(std::move(chunk))) break;
  }
  // The replies to the chunks before an error go out before it.
  pipeline.close_and_wait();
  if (spdlog::should_log(spdlog::level::debug)) {
    const StreamTimes& t = pipeline.times();
    spdlog::debug(
        "{}: {} chunks, {} rays in {:.3f} ms, {} engine calls; handler reading {:.3f} ms, waiting for the "
        "tracer {:.3f} ms; tracer answering {:.3f} ms, waiting for the writer {:.3f} ms; writer writing "
        "{:.3f} ms",
        Traits::kStream, position.chunk, position.first_ray,
        std::chrono::duration<double, std::milli>(Clock::now() - stream_start).count(), t.groups,
        t.reading * 1e3, t.waiting_to_queue * 1e3, t.tracing * 1e3, t.waiting_to_reply * 1e3,
        t.writing * 1e3);
  }
  if (!tracer_status.ok()) return tracer_status;
  if (!status.ok()) return status;
  if (pipeline.write_failed()) {
    return grpc::Status(grpc::StatusCode::CANCELLED, "the client went away before all replies to its " +
                                                         std::to_string(position.chunk) +
                                                         " chunks were written");
  }
  if (context->IsCancelled()) {
    return grpc::Status(grpc::StatusCode::CANCELLED, "the client cancelled the stream after " +
                                                         std::to_string(position.chunk) + " chunks");
  }
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::Intersect(grpc::ServerContext* context, const v1::QueryRequest* request,
                                          v1::IntersectResponse* response) {
  const auto start = Clock::now();
  return finish(context, "Intersect", answer<QueryKind::kClosestHit>(context, *request, response),
                request->batch().ray_count(), start);
}

grpc::Status SceneQueryService::Occluded(grpc::ServerContext* context, const v1::QueryRequest* request,
                                         v1::OccludedResponse* response) {
  const auto start = Clock::now();
  return finish(context, "Occluded", answer<QueryKind::kAnyHit>(context, *request, response),
                request->batch().ray_count(), start);
}

template <class Response, class Handler>
grpc::Status SceneQueryService::serve_unary(grpc::ServerContext* context,
                                            grpc::ServerUnaryStreamer<v1::QueryRequest, Response>* streamer,
                                            const char* method, const Handler& handler) {
  v1::QueryRequest request;
  if (!streamer->Read(&request)) {
    if (context->IsCancelled()) {
      return finish(context, method, grpc::Status(grpc::StatusCode::CANCELLED, "cancelled by the client"), 0,
                    Clock::now());
    }
    return finish(
        context, method,
        grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, std::string("the request could not be parsed as ") +
                                                             v1::QueryRequest::descriptor()->full_name() +
                                                             " (malformed protobuf bytes, or no message)"),
        0, Clock::now());
  }
  Response response;
  const grpc::Status status = handler(&request, &response);
  if (!status.ok()) return status;
  // The reply goes out with the status, as a unary call's does.
  if (!streamer->Write(response, grpc::WriteOptions().set_last_message())) {
    return grpc::Status(grpc::StatusCode::CANCELLED, "the client went away before the reply was written");
  }
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::StreamedIntersect(
    grpc::ServerContext* context,
    grpc::ServerUnaryStreamer<v1::QueryRequest, v1::IntersectResponse>* streamer) {
  return serve_unary(context, streamer, "Intersect",
                     [&](const v1::QueryRequest* request, v1::IntersectResponse* response) {
                       return Intersect(context, request, response);
                     });
}

grpc::Status SceneQueryService::StreamedOccluded(
    grpc::ServerContext* context,
    grpc::ServerUnaryStreamer<v1::QueryRequest, v1::OccludedResponse>* streamer) {
  return serve_unary(context, streamer, "Occluded",
                     [&](const v1::QueryRequest* request, v1::OccludedResponse* response) {
                       return Occluded(context, request, response);
                     });
}

grpc::Status SceneQueryService::GetSceneInfo(grpc::ServerContext*, const v1::GetSceneInfoRequest*,
                                             v1::SceneInfo* response) {
  const SceneStore& store = engine_.store();
  const Manifest& manifest = store.manifest();
  response->set_store_path(store.directory());
  response->set_format_version(manifest.format_version);
  response->set_packed_by_version(manifest.outcore_version);
  response->set_triangle_count(manifest.triangle_count);
  response->set_degenerate_count(manifest.degenerate_count);
  response->set_brick_count(store.brick_count());
  response->set_upper_depth(manifest.upper.depth());
  for (const float value : {manifest.bounds.lo.x, manifest.bounds.lo.y, manifest.bounds.lo.z}) {
    response->add_bounds_lo(value);
  }
  for (const float value : {manifest.bounds.hi.x, manifest.bounds.hi.y, manifest.bounds.hi.z}) {
    response->add_bounds_hi(value);
  }
  for (const InputRecord& input : manifest.inputs) {
    v1::SceneInput* out = response->add_inputs();
    out->set_spec(input.spec);
    out->set_triangle_count(input.triangle_count);
    out->set_degenerate_count(input.degenerate_count);
  }
  response->set_brick_accel(engine_.cache().builder().name());
  response->set_eviction_policy(engine_.cache().policy().name());
  response->set_cache_budget_bytes(engine_.cache().budget_bytes());
  response->set_server_version(OUTCORE_VERSION);
  response->set_max_message_bytes(options_.max_message_bytes);
  response->set_shared_payloads(options_.shared_payloads);
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::GetStats(grpc::ServerContext*, const v1::GetStatsRequest*,
                                         v1::ServerStats* response) {
  const ServiceCounters c = counters();
  response->set_requests(c.requests);
  response->set_failed_requests(c.failed_requests);
  response->set_cancelled_requests(c.cancelled_requests);
  response->set_rays(c.rays);
  response->set_rays_hit(c.rays_hit);
  response->set_invalid_rays(c.invalid_rays);
  response->set_seconds_tracing(c.seconds_tracing);
  response->set_brick_visits(c.brick_visits);
  response->set_proxy_tests(c.proxy_tests);
  response->set_bricks_skipped_by_proxy(c.bricks_skipped_by_proxy);
  response->set_rays_traced_ahead(c.rays_traced_ahead);
  response->set_rays_in_brick_set(c.rays_in_brick_set);
  const CacheCounters cache = engine_.cache().counters();
  response->set_cache_hits(cache.hits);
  response->set_cache_misses(cache.misses);
  response->set_brick_builds(cache.builds);
  response->set_evictions(cache.evictions);
  response->set_bytes_built(cache.bytes_built);
  response->set_build_seconds(cache.build_seconds);
  response->set_resident_bytes(cache.resident_bytes);
  response->set_peak_resident_bytes(cache.peak_resident_bytes);
  response->set_resident_bricks(cache.resident_bricks);
  response->set_cache_budget_bytes(engine_.cache().budget_bytes());
  response->set_eviction_policy(engine_.cache().policy().name());
  response->set_proxy_bytes(engine_.proxies() != nullptr ? engine_.proxies()->memory_bytes() : 0);
  {
    std::lock_guard lock(store_changed_mutex_);
    response->set_store_changed(store_changed_);
  }
  if (const SubtreeTier* tier = engine_.cache().subtree_tier()) {
    const SubtreeTierCounters& t = cache.subtree;
    response->set_subtree_dir(tier->options().directory);
    response->set_subtree_loads(t.loads);
    response->set_subtree_loads_checked(t.loads_checked);
    response->set_subtree_loads_kept(t.loads_kept);
    response->set_subtree_writes(t.writes);
    response->set_subtree_rejects(t.rejected());
    response->set_subtree_bytes_read(t.bytes_read);
    response->set_subtree_bytes_written(t.bytes_written);
    response->set_subtree_load_seconds(t.load_seconds);
    response->set_subtree_files(t.files);
    response->set_subtree_file_bytes(t.bytes);
    response->set_subtree_write_failures(t.write_failures);
    response->set_subtree_writes_too_large(t.writes_too_large);
    response->set_subtree_files_evicted(t.files_evicted);
    response->set_subtree_write_seconds(t.write_seconds);
  }
  return grpc::Status::OK;
}

void SceneQueryService::check_store() {
  {
    std::lock_guard lock(store_changed_mutex_);
    if (!store_changed_.empty()) return;  // said once; the scene served stays the same
  }
  const Status status = engine_.store().check_unchanged_on_disk();
  if (status.ok()) return;
  const std::string what =
      status.message() +
      "; this server goes on serving the scene it opened (restart it to serve the new one)";
  spdlog::warn("{}", what);
  std::lock_guard lock(store_changed_mutex_);
  store_changed_ = what;
}

ServiceCounters SceneQueryService::counters() const {
  ServiceCounters c;
  c.requests = requests_.load(std::memory_order_relaxed);
  c.failed_requests = failed_requests_.load(std::memory_order_relaxed);
  c.cancelled_requests = cancelled_requests_.load(std::memory_order_relaxed);
  c.rays = rays_.load(std::memory_order_relaxed);
  c.rays_hit = rays_hit_.load(std::memory_order_relaxed);
  c.invalid_rays = invalid_rays_.load(std::memory_order_relaxed);
  c.seconds_tracing = static_cast<double>(nanoseconds_tracing_.load(std::memory_order_relaxed)) * 1e-9;
  c.brick_visits = brick_visits_.load(std::memory_order_relaxed);
  c.proxy_tests = proxy_tests_.load(std::memory_order_relaxed);
  c.bricks_skipped_by_proxy = bricks_skipped_by_proxy_.load(std::memory_order_relaxed);
  c.rays_traced_ahead = rays_traced_ahead_.load(std::memory_order_relaxed);
  c.rays_in_brick_set = rays_in_brick_set_.load(std::memory_order_relaxed);
  return c;
}

}  // namespace outcore::server
