#include "server/scene_query_service.h"

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/method_handler.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cassert>
#include <cstring>
#include <vector>

#include "server/grpc_status.h"
#include "server/server_security.h"
#include "server/stream_pipeline.h"
#include "server/wire_mapping.h"

namespace outcore::server {

namespace {

using Clock = std::chrono::steady_clock;

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
    return invalid_argument(
        where(position) +
        ": shared payloads are for the unary calls (Intersect, Occluded, CountIntersections), not streams");
  }
  if (request.hit_fields() != v1::HIT_FIELDS_ALL &&
      (kKind != QueryKind::kClosestHit || wire::hit_record_bytes(request.hit_fields()) == 0)) {
    return invalid_argument(where(position) + ": hit_fields " + std::to_string(request.hit_fields()) +
                            (kKind == QueryKind::kClosestHit
                                 ? " is not a HitFields value (0 all, 1 t, 2 t and ids)"
                                 : " applies to Intersect only (leave it HIT_FIELDS_ALL)"));
  }
  auto rays = decode_ray_batch(request.batch(), storage);
  if (!rays.ok()) return rays.status().with_context(where(position));
  const uint64_t n = rays->size();
  const uint64_t reply_bytes = n * reply_bytes_per_ray<kKind>(request) + kReplyOverheadBytes;
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

QueryOptions SceneQueryService::options_of(const v1::QueryRequest& request,
                                           const std::shared_ptr<const DynamicSnapshot>& dynamic) {
  QueryOptions options;
  options.reorder = !request.no_reorder();
  options.strict = request.strict();
  options.dynamic_snapshot = dynamic;
  options.only_bricks.assign(request.only_bricks().begin(), request.only_bricks().end());
  return options;
}

template <QueryKind kKind>
Status SceneQueryService::trace(std::span<const Ray> rays, uint8_t* out, const v1::QueryRequest& request,
                                const std::shared_ptr<const DynamicSnapshot>& dynamic, QueryStats* stats) {
  const QueryOptions query_options = options_of(request, dynamic);
  const uint64_t n = rays.size();
  Status status;
  if constexpr (kKind == QueryKind::kClosestHit) {
    // Hits go straight into `out` (a reply's bytes); a std::string's buffer
    // is float-aligned in practice, the fallback only costs a copy. Fewer
    // fields than all are traced into this thread's scratch and packed.
    if (request.hit_fields() != v1::HIT_FIELDS_ALL) {
      thread_local std::vector<Hit> scratch;
      scratch.resize(n);
      status = engine_.intersect(rays, scratch, query_options, stats);
      if (status.ok()) wire::pack_hit_fields(scratch, request.hit_fields(), out);
      // A huge batch's scratch is not kept for the thread's life.
      if (scratch.capacity() * sizeof(Hit) > kKeepSharedBufferBytes) std::vector<Hit>().swap(scratch);
    } else if (reinterpret_cast<uintptr_t>(out) % alignof(Hit) == 0) {
      status = engine_.intersect(rays, std::span<Hit>(reinterpret_cast<Hit*>(out), n), query_options, stats);
    } else {
      std::vector<Hit> hits(n);
      status = engine_.intersect(rays, hits, query_options, stats);
      if (n) std::memcpy(out, static_cast<const void*>(hits.data()), n * sizeof(Hit));
    }
  } else if constexpr (kKind == QueryKind::kAnyHit) {
    status = engine_.occluded(rays, std::span<uint8_t>(out, n), query_options, stats);
  } else {
    // Counts only (a shared CountIntersections): `out` is a call buffer's
    // start, allocated with new, so aligned for uint32_t.
    assert(reinterpret_cast<uintptr_t>(out) % alignof(uint32_t) == 0);
    // The engine resets every ray's count, as it does every hit record.
    status = engine_.all_hits(rays, std::span<uint32_t>(reinterpret_cast<uint32_t*>(out), n), nullptr,
                              query_options, stats);
  }
  if (status.ok()) counters_.add_answered(*stats);
  return status;
}

// The shared-memory call and the streams (shared_memory_call.cpp,
// streamed_call.cpp) trace with these.
template Status SceneQueryService::trace<QueryKind::kClosestHit>(
    std::span<const Ray>, uint8_t*, const v1::QueryRequest&, const std::shared_ptr<const DynamicSnapshot>&,
    QueryStats*);
template Status SceneQueryService::trace<QueryKind::kAnyHit>(std::span<const Ray>, uint8_t*,
                                                             const v1::QueryRequest&,
                                                             const std::shared_ptr<const DynamicSnapshot>&,
                                                             QueryStats*);
template Status SceneQueryService::trace<QueryKind::kAllHits>(std::span<const Ray>, uint8_t*,
                                                              const v1::QueryRequest&,
                                                              const std::shared_ptr<const DynamicSnapshot>&,
                                                              QueryStats*);

Expected<std::shared_ptr<const DynamicSnapshot>> SceneQueryService::dynamic_for(
    const v1::QueryRequest& request) const {
  if (!request.has_dynamic_version()) return engine_.dynamic().latest();
  return engine_.dynamic().at(request.dynamic_version());
}
template Expected<std::span<const Ray>> SceneQueryService::check_request<QueryKind::kClosestHit>(
    const v1::QueryRequest&, const BatchPosition&, std::vector<Ray>&) const;
template Expected<std::span<const Ray>> SceneQueryService::check_request<QueryKind::kAnyHit>(
    const v1::QueryRequest&, const BatchPosition&, std::vector<Ray>&) const;
template Expected<std::span<const Ray>> SceneQueryService::check_request<QueryKind::kAllHits>(
    const v1::QueryRequest&, const BatchPosition&, std::vector<Ray>&) const;

bool SceneQueryService::worth_keeping(const CallBuffers& buffers) {
  return buffers.rays.capacity() * sizeof(Ray) + buffers.answers.capacity() <= kKeepSharedBufferBytes;
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
  auto dynamic = dynamic_for(request);
  if (!dynamic.ok()) return to_grpc_status(dynamic.status().with_context("request.dynamic_version"));
  std::string* payload = Traits::payload(response);
  payload->resize(n * reply_bytes_per_ray<kKind>(request));
  QueryStats stats;
  const Status status =
      trace<kKind>(*rays, reinterpret_cast<uint8_t*>(payload->data()), request, *dynamic, &stats);
  if (!status.ok()) {
    payload->clear();
    return to_grpc_status(status);
  }
  set_reply_header(response, n, request.sequence());
  if constexpr (kKind == QueryKind::kClosestHit) response->set_hit_fields(request.hit_fields());
  response->set_dynamic_version((*dynamic)->version);
  wire::to_wire(stats, response->mutable_stats());
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::authorize(const grpc::ServerContext& context) const {
  return check_bearer_token(context, options_.auth_token);
}

grpc::Status SceneQueryService::finish(grpc::ServerContext* context, const char* method,
                                       const grpc::Status& status, uint64_t rays, Clock::time_point start) {
  // An answer the client no longer waits for (it cancelled, or the server's
  // drain cancelled the call) was never delivered: it is no success.
  const bool cancelled = status.error_code() == grpc::StatusCode::CANCELLED || context->IsCancelled();
  counters_.count_request(!status.ok() || cancelled, cancelled);
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
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
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

grpc::Status SceneQueryService::GetSceneInfo(grpc::ServerContext* context, const v1::GetSceneInfoRequest*,
                                             v1::SceneInfo* response) {
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const SceneStore& store = engine_.store();
  const Manifest& manifest = store.manifest();
  response->set_store_path(store.directory());
  response->set_format_version(manifest.format_version);
  response->set_packed_by_version(manifest.outcore_version);
  response->set_triangle_count(manifest.triangle_count);
  response->set_degenerate_count(manifest.degenerate_count);
  response->set_brick_count(store.brick_count());
  response->set_upper_depth(manifest.upper.depth());
  const auto add_point = [](google::protobuf::RepeatedField<float>* out, const auto& p) {
    out->Add(p.x);
    out->Add(p.y);
    out->Add(p.z);
  };
  add_point(response->mutable_bounds_lo(), manifest.bounds.lo);
  add_point(response->mutable_bounds_hi(), manifest.bounds.hi);
  for (const BrickRecord& brick : manifest.bricks) {
    v1::BrickSummary* out = response->add_bricks();
    add_point(out->mutable_bounds_lo(), brick.bounds.lo);
    add_point(out->mutable_bounds_hi(), brick.bounds.hi);
    out->set_triangle_count(brick.triangle_count);
    out->set_size_bytes(brick.size_bytes);
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
  response->set_shared_every_hit_payloads(options_.shared_payloads);
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::GetStats(grpc::ServerContext* context, const v1::GetStatsRequest*,
                                         v1::ServerStats* response) {
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const ServiceCounters c = counters();
  response->set_requests(c.requests);
  response->set_failed_requests(c.failed_requests);
  response->set_cancelled_requests(c.cancelled_requests);
  set_answered_sums(c.answered, response);
  const CacheCounters cache = engine_.cache().counters();
  response->set_cache_hits(cache.hits);
  response->set_cache_misses(cache.misses);
  response->set_brick_builds(cache.builds);
  response->set_brick_rebuilds(cache.rebuilds);
  const std::vector<std::string> structures = brick_accel_names();
  for (std::size_t s = 0; s < structures.size() && s < kMaxBrickStructures; ++s) {
    if (cache.builds_by_structure[s] > 0)
      (*response->mutable_brick_builds_by_structure())[structures[s]] = cache.builds_by_structure[s];
  }
  response->set_evictions(cache.evictions);
  {
    const std::shared_ptr<const DynamicSnapshot> dynamic = engine_.dynamic().latest();
    const DynamicScene::Counters d = engine_.dynamic().counters();
    response->set_dynamic_version(dynamic->version);
    response->set_dynamic_meshes(dynamic->meshes.size());
    response->set_dynamic_instances(dynamic->instances.size());
    response->set_dynamic_triangles(dynamic->triangle_count());
    response->set_dynamic_mesh_refits(d.mesh_refits);
    response->set_dynamic_mesh_rebuilds(d.mesh_rebuilds);
    response->set_dynamic_top_refits(d.top_refits);
    response->set_dynamic_top_rebuilds(d.top_rebuilds);
  }
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
    response->set_subtree_loads_recycled(t.loads_recycled);
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
  return counters_.snapshot();
}

}  // namespace outcore::server
