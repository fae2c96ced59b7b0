#include "server/scene_query_service.h"

#include <spdlog/spdlog.h>

#include <cstring>
#include <vector>

#include "server/grpc_status.h"

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

void fill_stats(const QueryStats& stats, v1::QueryStats* out) {
  out->set_rays(stats.rays);
  out->set_invalid_rays(stats.invalid_rays);
  out->set_rays_hit(stats.rays_hit);
  out->set_brick_visits(stats.brick_visits);
  out->set_brick_acquisitions(stats.brick_acquisitions);
  out->set_cache_hits(stats.cache_hits);
  out->set_cache_misses(stats.cache_misses);
  out->set_brick_builds(stats.brick_builds);
  out->set_evictions(stats.evictions);
  out->set_seconds_total(stats.seconds_total);
  out->set_seconds_build(stats.seconds_build);
}

bool deadline_passed(const grpc::ServerContext* context) {
  return context->deadline() <= std::chrono::system_clock::now();
}

}  // namespace

SceneQueryService::SceneQueryService(QueryEngine& engine, const ServiceOptions& options)
    : engine_(engine), options_(options) {}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer(grpc::ServerContext* context, const v1::QueryRequest& request,
                                       const BatchPosition& position, Response* response) {
  using Traits = KindTraits<kKind>;
  std::vector<Ray> storage;
  auto rays = decode_ray_batch(request.batch(), storage);
  if (!rays.ok()) return to_grpc_status(rays.status().with_context(where(position)));
  const uint64_t n = rays->size();
  const uint64_t reply_bytes = n * Traits::kReplyBytesPerRay + kReplyOverheadBytes;
  if (reply_bytes > options_.max_message_bytes) {
    return to_grpc_status(resource_exhausted(where(position) + ": the reply to " + std::to_string(n) +
                                             " rays would take about " + std::to_string(reply_bytes) +
                                             " bytes, over the server's max message size of " +
                                             std::to_string(options_.max_message_bytes) +
                                             " bytes (--max-message-mb); send fewer rays per message"));
  }
  const Status valid = check_rays(*rays, position, request.strict());
  if (!valid.ok()) return to_grpc_status(valid);
  if (context->IsCancelled()) {
    return grpc::Status(grpc::StatusCode::CANCELLED,
                        where(position) + " cancelled by the client before tracing");
  }
  if (deadline_passed(context)) {
    return grpc::Status(
        grpc::StatusCode::DEADLINE_EXCEEDED,
        "the deadline expired before " + where(position) + " (" + std::to_string(n) + " rays) was traced");
  }

  QueryOptions query_options;
  query_options.reorder = !request.no_reorder();
  query_options.strict = request.strict();
  QueryStats stats;
  std::string* payload = Traits::payload(response);
  payload->resize(n * Traits::kReplyBytesPerRay);
  Status status;
  if constexpr (kKind == QueryKind::kClosestHit) {
    // Hits go straight into the reply's bytes; a std::string's buffer is
    // float-aligned in practice, the fallback only costs a copy.
    if (reinterpret_cast<uintptr_t>(payload->data()) % alignof(Hit) == 0) {
      status = engine_.intersect(*rays, std::span<Hit>(reinterpret_cast<Hit*>(payload->data()), n),
                                 query_options, &stats);
    } else {
      std::vector<Hit> hits(n);
      status = engine_.intersect(*rays, hits, query_options, &stats);
      if (n) std::memcpy(payload->data(), static_cast<const void*>(hits.data()), n * sizeof(Hit));
    }
  } else {
    status = engine_.occluded(*rays, std::span<uint8_t>(reinterpret_cast<uint8_t*>(payload->data()), n),
                              query_options, &stats);
  }
  if (!status.ok()) {
    payload->clear();
    return to_grpc_status(position.streamed ? status.with_context(where(position)) : status);
  }
  response->set_layout_version(1);
  response->set_ray_count(n);
  response->set_sequence(request.sequence());
  fill_stats(stats, response->mutable_stats());
  rays_.fetch_add(stats.rays, std::memory_order_relaxed);
  rays_hit_.fetch_add(stats.rays_hit, std::memory_order_relaxed);
  invalid_rays_.fetch_add(stats.invalid_rays, std::memory_order_relaxed);
  nanoseconds_tracing_.fetch_add(static_cast<uint64_t>(stats.seconds_total * 1e9), std::memory_order_relaxed);
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::finish(const char* method, const grpc::Status& status, uint64_t rays,
                                       Clock::time_point start) {
  requests_.fetch_add(1, std::memory_order_relaxed);
  if (!status.ok()) failed_requests_.fetch_add(1, std::memory_order_relaxed);
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
                                             grpc::ServerReaderWriter<Response, v1::QueryRequest>* stream) {
  BatchPosition position;
  position.streamed = true;
  v1::QueryRequest request;
  Response response;
  while (stream->Read(&request)) {
    const auto start = Clock::now();
    response.Clear();  // keeps the payload's capacity for the next chunk
    const grpc::Status status =
        finish(KindTraits<kKind>::kStream, answer<kKind>(context, request, position, &response),
               request.batch().ray_count(), start);
    if (!status.ok()) return status;
    if (!stream->Write(response)) {
      return grpc::Status(grpc::StatusCode::CANCELLED,
                          "the client went away before the reply to chunk " + std::to_string(position.chunk));
    }
    position.first_ray += response.ray_count();
    ++position.chunk;
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
  return finish("Intersect", answer<QueryKind::kClosestHit>(context, *request, BatchPosition{}, response),
                request->batch().ray_count(), start);
}

grpc::Status SceneQueryService::Occluded(grpc::ServerContext* context, const v1::QueryRequest* request,
                                         v1::OccludedResponse* response) {
  const auto start = Clock::now();
  return finish("Occluded", answer<QueryKind::kAnyHit>(context, *request, BatchPosition{}, response),
                request->batch().ray_count(), start);
}

grpc::Status SceneQueryService::IntersectStream(
    grpc::ServerContext* context, grpc::ServerReaderWriter<v1::IntersectResponse, v1::QueryRequest>* stream) {
  return serve_stream<QueryKind::kClosestHit>(context, stream);
}

grpc::Status SceneQueryService::OccludedStream(
    grpc::ServerContext* context, grpc::ServerReaderWriter<v1::OccludedResponse, v1::QueryRequest>* stream) {
  return serve_stream<QueryKind::kAnyHit>(context, stream);
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
  return grpc::Status::OK;
}

grpc::Status SceneQueryService::GetStats(grpc::ServerContext*, const v1::GetStatsRequest*,
                                         v1::ServerStats* response) {
  const ServiceCounters c = counters();
  response->set_requests(c.requests);
  response->set_failed_requests(c.failed_requests);
  response->set_rays(c.rays);
  response->set_rays_hit(c.rays_hit);
  response->set_invalid_rays(c.invalid_rays);
  response->set_seconds_tracing(c.seconds_tracing);
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
  return grpc::Status::OK;
}

ServiceCounters SceneQueryService::counters() const {
  ServiceCounters c;
  c.requests = requests_.load(std::memory_order_relaxed);
  c.failed_requests = failed_requests_.load(std::memory_order_relaxed);
  c.rays = rays_.load(std::memory_order_relaxed);
  c.rays_hit = rays_hit_.load(std::memory_order_relaxed);
  c.invalid_rays = invalid_rays_.load(std::memory_order_relaxed);
  c.seconds_tracing = static_cast<double>(nanoseconds_tracing_.load(std::memory_order_relaxed)) * 1e-9;
  return c;
}

}  // namespace outcore::server
