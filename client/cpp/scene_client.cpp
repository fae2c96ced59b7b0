#include "client/cpp/scene_client.h"

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/client_unary_call.h>
#include <grpcpp/impl/rpc_method.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <chrono>
#include <cstring>
#include <string_view>
#include <thread>

#include "client/cpp/raw_query_messages.h"
#include "core/util/loopback_address.h"
#include "proto/outcore/v1/grpc_code_names.h"
#include "proto/outcore/v1/hit_fields_wire.h"
#include "proto/outcore/v1/query_stats_wire.h"
#include "proto/outcore/v1/shared_payload_wire.h"

namespace outcore::client {

static_assert(std::endian::native == std::endian::little, "the wire layouts are little-endian");

namespace {

// Room in a message for everything but its rays or hits.
constexpr uint64_t kMessageOverheadBytes = 1024;
// Both ways carry at most 32 bytes per ray (F32X8 rays, hit records).
constexpr uint64_t kWireBytesPerRay = 32;
// Assumed when a server does not report its limit (gRPC's usual default).
constexpr uint64_t kDefaultMaxMessageBytes = uint64_t{4} << 20;
// Shared-memory objects kept for reuse once their call is done.
constexpr std::size_t kSpareObjects = 4;
// Where the rays start in a shared object (after its header) and where the
// answers start: after the rays, cache-line aligned.
constexpr uint64_t kRaysOffset = SharedMemoryObject::kHeaderBytes;
constexpr uint64_t answers_offset(uint64_t ray_bytes) {
  return kRaysOffset + (ray_bytes + 63) / 64 * 64;
}
// Objects are made a little larger than asked (up to an eighth of the next
// power of two, whole MiB), so batches that grow slowly reuse one object.
uint64_t object_size(uint64_t bytes) {
  const uint64_t step = std::max<uint64_t>(uint64_t{1} << 20, std::bit_ceil(bytes) / 8);
  return (bytes + step - 1) / step * step;
}

// memcpy over the cores for the shared-memory copies (32 MiB each way for
// 1 M hits), which the server waits on.
void parallel_copy(void* destination, const void* source, std::size_t bytes) {
  constexpr std::size_t kStep = std::size_t{1} << 20;
  if (bytes <= 2 * kStep) {
    std::memcpy(destination, source, bytes);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, (bytes + kStep - 1) / kStep),
                    [&](const tbb::blocked_range<std::size_t>& steps) {
                      const std::size_t first = steps.begin() * kStep;
                      const std::size_t last = std::min(bytes, steps.end() * kStep);
                      std::memcpy(static_cast<char*>(destination) + first,
                                  static_cast<const char*>(source) + first, last - first);
                    });
}

void set_deadline(grpc::ClientContext& context, double seconds) {
  if (seconds > 0) {
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::duration_cast<std::chrono::system_clock::duration>(
                             std::chrono::duration<double>(seconds)));
  }
}

// Per reply type: the stub's methods and the reply's payload.
grpc::Status call_unary(v1::SceneQuery::Stub& stub, grpc::ClientContext* context,
                        const v1::QueryRequest& request, v1::IntersectResponse* response) {
  return stub.Intersect(context, request, response);
}
grpc::Status call_unary(v1::SceneQuery::Stub& stub, grpc::ClientContext* context,
                        const v1::QueryRequest& request, v1::OccludedResponse* response) {
  return stub.Occluded(context, request, response);
}
const std::string& payload(const v1::IntersectResponse& response) {
  return response.hits();
}
const std::string& payload(const v1::OccludedResponse& response) {
  return response.occluded();
}
const char* method_name(const v1::IntersectResponse*) {
  return "Intersect";
}
const char* method_name(const v1::OccludedResponse*) {
  return "Occluded";
}
// Counts go through shared memory too (their 4-byte answers are the payload).
grpc::Status call_unary(v1::SceneQuery::Stub& stub, grpc::ClientContext* context,
                        const v1::QueryRequest& request, v1::CountResponse* response) {
  return stub.CountIntersections(context, request, response);
}
const std::string& payload(const v1::CountResponse& response) {
  return response.counts();
}
const char* method_name(const v1::CountResponse*) {
  return "CountIntersections";
}

void fill_request(std::span<const Ray> rays, uint64_t sequence, const CallOptions& options,
                  v1::QueryRequest& request) {
  v1::RayBatch* batch = request.mutable_batch();
  batch->set_layout_version(1);
  batch->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  batch->set_ray_count(rays.size());
  batch->set_rays(reinterpret_cast<const char*>(rays.data()), rays.size_bytes());
  request.set_strict(options.strict);
  request.set_no_reorder(options.no_reorder);
  request.set_sequence(sequence);
  request.mutable_only_bricks()->Add(options.only_bricks.begin(), options.only_bricks.end());
}

// The hit fields a request asks for (closest hits only), and the bytes of
// one ray's answer in its reply on the bytes path (0: not a HitFields value).
v1::HitFields hit_fields_of(const v1::IntersectResponse*, const CallOptions& options) {
  return options.hit_fields;
}
v1::HitFields hit_fields_of(const v1::OccludedResponse*, const CallOptions&) {
  return v1::HIT_FIELDS_ALL;
}
uint32_t wire_bytes_per_ray(const v1::IntersectResponse* kind, const CallOptions& options) {
  return wire::hit_record_bytes(hit_fields_of(kind, options));
}
uint32_t wire_bytes_per_ray(const v1::OccludedResponse*, const CallOptions&) {
  return 1;
}

void add_stats(const v1::QueryStats& from, CallStats* to) {
  if (to == nullptr) return;
  ++to->messages;
  wire::add_to_wire(wire::from_wire(from), &to->engine);
}

// A bytes-path reply to `count` rays: checked, its answers copied to `out`
// (unpacked into Hit records through `scratch` when it carries fewer
// fields), its figures added to `stats` and its rays to `progress`.
Status take_reply(const RawQueryReply& reply, uint64_t count, uint64_t sequence, uint32_t wire_bytes,
                  uint32_t out_bytes, v1::HitFields fields, uint8_t* out, std::vector<uint8_t>& scratch,
                  CallStats* stats, ProgressBar* progress) {
  const bool packed = wire_bytes != out_bytes;
  if (packed) scratch.resize(count * wire_bytes);
  ReplyHeader header;
  OUTCORE_RETURN_IF_ERROR(decode_query_reply(
      reply, std::span<uint8_t>(packed ? scratch.data() : out, count * wire_bytes), header));
  if (header.layout_version != 1 || header.ray_count != count || header.answer_bytes != count * wire_bytes ||
      header.sequence != sequence || header.answers_in_shared) {
    return internal_error(
        "the server's reply to message " + std::to_string(sequence) + " is malformed: layout " +
        std::to_string(header.layout_version) + ", " + std::to_string(header.ray_count) + " rays in " +
        std::to_string(header.answer_bytes) + " bytes, sequence " + std::to_string(header.sequence) +
        " (expected " + std::to_string(count) + " rays in " + std::to_string(count * wire_bytes) +
        " bytes, sequence " + std::to_string(sequence) + ")");
  }
  if (packed)
    wire::unpack_hit_fields(scratch.data(), fields, std::span<Hit>(reinterpret_cast<Hit*>(out), count));
  add_stats(header.stats, stats);
  if (progress != nullptr) progress->advance(count);
  return Status::Ok();
}

}  // namespace

QueryStats to_query_stats(const v1::QueryStats& stats) {
  return wire::from_wire(stats);
}

Status from_grpc_status(const grpc::Status& status, const std::string& context) {
  if (status.ok()) return Status::Ok();
  StatusCode code = StatusCode::kInternal;
  switch (status.error_code()) {
    case grpc::StatusCode::INVALID_ARGUMENT: code = StatusCode::kInvalidArgument; break;
    case grpc::StatusCode::NOT_FOUND: code = StatusCode::kNotFound; break;
    case grpc::StatusCode::ALREADY_EXISTS: code = StatusCode::kAlreadyExists; break;
    case grpc::StatusCode::DATA_LOSS: code = StatusCode::kDataLoss; break;
    case grpc::StatusCode::FAILED_PRECONDITION: code = StatusCode::kFailedPrecondition; break;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: code = StatusCode::kResourceExhausted; break;
    case grpc::StatusCode::OUT_OF_RANGE: code = StatusCode::kOutOfRange; break;
    case grpc::StatusCode::PERMISSION_DENIED: code = StatusCode::kPermissionDenied; break;
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::DEADLINE_EXCEEDED: code = StatusCode::kCancelled; break;
    case grpc::StatusCode::UNAVAILABLE: code = StatusCode::kIoError; break;
    default: code = StatusCode::kInternal; break;
  }
  return Status(code,
                context + ": " + wire::grpc_code_name(status.error_code()) + ": " + status.error_message());
}

SceneClient::SceneClient(std::shared_ptr<grpc::Channel> channel, std::string address)
    : channel_(std::move(channel)), stub_(v1::SceneQuery::NewStub(channel_)), address_(std::move(address)) {}

Expected<std::unique_ptr<SceneClient>> SceneClient::connect(const std::string& address,
                                                            const ConnectOptions& options) {
  OUTCORE_RETURN_IF_ERROR(check_target_ports(address));
  grpc::ChannelArguments arguments;
  // The server's limit is the one that matters; ours must not be lower.
  arguments.SetMaxReceiveMessageSize(-1);
  arguments.SetMaxSendMessageSize(-1);
  OUTCORE_ASSIGN_OR_RETURN(std::shared_ptr<grpc::Channel> channel,
                           make_channel(address, options.security, arguments));
  std::unique_ptr<SceneClient> client(new SceneClient(std::move(channel), address));
  OUTCORE_ASSIGN_OR_RETURN(client->scene_, client->scene_info(options.timeout_seconds));
  const uint64_t max_message =
      client->scene_.max_message_bytes() ? client->scene_.max_message_bytes() : kDefaultMaxMessageBytes;
  client->max_chunk_rays_ =
      std::max<uint64_t>(1, (max_message - std::min(max_message, kMessageOverheadBytes)) / kWireBytesPerRay);
  client->use_shared_ =
      options.shared_memory && client->scene_.shared_payloads() && is_loopback_target(address);
  return client;
}

Expected<v1::SceneInfo> SceneClient::scene_info(double deadline_seconds) {
  grpc::ClientContext context;
  set_deadline(context, deadline_seconds);
  v1::SceneInfo info;
  const grpc::Status status = stub_->GetSceneInfo(&context, v1::GetSceneInfoRequest(), &info);
  if (!status.ok()) return from_grpc_status(status, "GetSceneInfo from " + address_);
  return info;
}

Expected<v1::ServerStats> SceneClient::stats(double deadline_seconds) {
  grpc::ClientContext context;
  set_deadline(context, deadline_seconds);
  v1::ServerStats stats;
  const grpc::Status status = stub_->GetStats(&context, v1::GetStatsRequest(), &stats);
  if (!status.ok()) return from_grpc_status(status, "GetStats from " + address_);
  return stats;
}

Status SceneClient::intersect(std::span<const Ray> rays, std::span<Hit> hits, const CallOptions& options,
                              CallStats* stats) {
  if (hits.size() != rays.size()) return invalid_argument("hits and rays differ in length");
  return run<v1::IntersectResponse>(
      rays, std::span<uint8_t>(reinterpret_cast<uint8_t*>(hits.data()), hits.size_bytes()), sizeof(Hit),
      options, stats);
}

Status SceneClient::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded,
                             const CallOptions& options, CallStats* stats) {
  if (occluded.size() != rays.size()) return invalid_argument("occlusion flags and rays differ in length");
  return run<v1::OccludedResponse>(rays, occluded, 1, options, stats);
}

Status SceneClient::every_hit_chunk(std::span<const Ray> rays, bool listing, std::vector<uint32_t>& counts,
                                    std::vector<Hit>* hits, const CallOptions& options, CallStats* stats) {
  v1::QueryRequest request;
  fill_request(rays, 0, options, request);
  grpc::ClientContext context;
  set_deadline(context, options.deadline_seconds);
  const char* method = listing ? "ListIntersections" : "CountIntersections";
  v1::ListResponse list;
  v1::CountResponse count;
  const grpc::Status status = listing ? stub_->ListIntersections(&context, request, &list)
                                      : stub_->CountIntersections(&context, request, &count);
  if (!status.ok()) return from_grpc_status(status, std::string(method) + " on " + address_);
  const std::string& bytes = listing ? list.counts() : count.counts();
  if (bytes.size() != rays.size() * 4)
    return internal_error(std::string("the server's reply to ") + method + " holds " +
                          std::to_string(bytes.size()) + " count bytes for " + std::to_string(rays.size()) +
                          " rays");
  const std::size_t before = counts.size();
  counts.resize(before + rays.size());
  std::memcpy(counts.data() + before, bytes.data(), bytes.size());
  add_stats(listing ? list.stats() : count.stats(), stats);
  if (!listing) return Status::Ok();
  uint64_t total = 0;
  for (std::size_t i = before; i < counts.size(); ++i) total += counts[i];
  if (list.hit_count() != total || list.hits().size() != total * sizeof(Hit))
    return internal_error("the server's reply to ListIntersections holds " +
                          std::to_string(list.hits().size()) + " hit bytes, its counts say " +
                          std::to_string(total) + " hits");
  const std::size_t at = hits->size();
  hits->resize(at + total);
  if (total > 0) std::memcpy(static_cast<void*>(hits->data() + at), list.hits().data(), list.hits().size());
  return Status::Ok();
}

Status SceneClient::count_intersections(std::span<const Ray> rays, std::span<uint32_t> counts,
                                        const CallOptions& options, CallStats* stats) {
  if (counts.size() != rays.size()) return invalid_argument("counts and rays differ in length");
  // Same host: as intersect(), when the server takes every-hit calls so
  // (SceneInfo.shared_every_hit_payloads; older servers refuse them).
  if (options.chunk_rays == 0 && rays.size() >= kSharedMinRays && scene_.shared_every_hit_payloads() &&
      use_shared_.load(std::memory_order_relaxed)) {
    bool send_bytes = false;
    const std::span<uint8_t> out(reinterpret_cast<uint8_t*>(counts.data()), counts.size_bytes());
    const Status shared =
        run_shared<v1::CountResponse>(rays, out, sizeof(uint32_t), options, stats, &send_bytes);
    if (!send_bytes) return shared;
  }
  std::vector<uint32_t> all;
  for (std::size_t from = 0; from < rays.size(); from += max_chunk_rays_) {
    const auto chunk = rays.subspan(from, std::min<std::size_t>(max_chunk_rays_, rays.size() - from));
    OUTCORE_RETURN_IF_ERROR(every_hit_chunk(chunk, false, all, nullptr, options, stats));
  }
  std::copy(all.begin(), all.end(), counts.begin());
  return Status::Ok();
}

Status SceneClient::list_intersections(std::span<const Ray> rays, std::span<uint32_t> counts,
                                       std::vector<Hit>& hits, const CallOptions& options, CallStats* stats) {
  if (counts.size() != rays.size()) return invalid_argument("counts and rays differ in length");
  std::vector<uint32_t> all;
  hits.clear();
  std::size_t chunk_rays = max_chunk_rays_;
  for (std::size_t from = 0; from < rays.size();) {
    const auto chunk = rays.subspan(from, std::min<std::size_t>(chunk_rays, rays.size() - from));
    const Status status = every_hit_chunk(chunk, true, all, &hits, options, stats);
    // A chunk whose hits would not fit a message is sent again in quarters.
    if (status.code() == StatusCode::kResourceExhausted && chunk_rays > 1) {
      chunk_rays = std::max<std::size_t>(1, chunk_rays / 4);
      continue;
    }
    OUTCORE_RETURN_IF_ERROR(status);
    from += chunk.size();
  }
  std::copy(all.begin(), all.end(), counts.begin());
  return Status::Ok();
}

Status SceneClient::query_points(std::span<const Vec3f> points, v1::PointQueryKind kind, std::string& answers,
                                 const CallOptions& options, CallStats* stats) {
  answers.clear();
  // A point's request (12 bytes) and answer (at most 44) fit where a ray's
  // request (32) and hit (32) do.
  const std::size_t chunk_points = std::max<std::size_t>(1, max_chunk_rays_ * 32 / 44);
  for (std::size_t from = 0; from < points.size(); from += chunk_points) {
    const auto chunk = points.subspan(from, std::min(chunk_points, points.size() - from));
    v1::PointRequest request;
    request.set_layout_version(1);
    request.set_kind(kind);
    request.set_point_count(chunk.size());
    request.set_points(reinterpret_cast<const char*>(chunk.data()), chunk.size_bytes());
    request.set_strict(options.strict);
    grpc::ClientContext context;
    set_deadline(context, options.deadline_seconds);
    v1::PointResponse response;
    const grpc::Status status = stub_->QueryPoints(&context, request, &response);
    if (!status.ok()) return from_grpc_status(status, "QueryPoints on " + address_);
    if (response.point_count() != chunk.size())
      return internal_error("the server answered " + std::to_string(response.point_count()) + " points of " +
                            std::to_string(chunk.size()));
    answers += response.answers();
    add_stats(response.stats(), stats);
  }
  return Status::Ok();
}

Expected<std::unique_ptr<SharedMemoryObject>> SceneClient::take_object(uint64_t bytes) {
  {
    std::lock_guard lock(objects_mutex_);
    // The smallest spare that fits.
    auto best = spare_objects_.end();
    for (auto it = spare_objects_.begin(); it != spare_objects_.end(); ++it) {
      if ((*it)->size() >= bytes && (best == spare_objects_.end() || (*it)->size() < (*best)->size()))
        best = it;
    }
    if (best != spare_objects_.end()) {
      std::unique_ptr<SharedMemoryObject> object = std::move(*best);
      spare_objects_.erase(best);
      return object;
    }
  }
  // Objects of clients that died without closing stay in /dev/shm until
  // someone removes them: the first client of each process does.
  static std::once_flag orphans_removed;
  std::call_once(orphans_removed, [] { SharedMemoryObject::remove_orphans("cpp"); });
  OUTCORE_ASSIGN_OR_RETURN(SharedMemoryObject created,
                           SharedMemoryObject::create("cpp-" + std::to_string(getpid()), object_size(bytes)));
  return std::make_unique<SharedMemoryObject>(std::move(created));
}

bool SceneClient::shared_refused(const grpc::ClientContext& context) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto [first, last] = trailers.equal_range(wire::kSharedRefusedKey);
  return std::any_of(first, last, [](const auto& entry) {
    return std::string_view(entry.second.data(), entry.second.size()) == wire::kSharedRefusedValue;
  });
}

void SceneClient::stop_using_shared() {
  use_shared_.store(false, std::memory_order_relaxed);
  std::lock_guard lock(objects_mutex_);
  spare_objects_.clear();  // unlinks them: /dev/shm is freed now
}

void SceneClient::give_back_object(std::unique_ptr<SharedMemoryObject> object) {
  std::lock_guard lock(objects_mutex_);
  if (spare_objects_.size() < kSpareObjects) {
    spare_objects_.push_back(std::move(object));
    return;
  }
  // Keep the largest ones.
  auto smallest = std::min_element(spare_objects_.begin(), spare_objects_.end(),
                                   [](const auto& a, const auto& b) { return a->size() < b->size(); });
  if ((*smallest)->size() < object->size()) *smallest = std::move(object);
}

template <class Response>
Status SceneClient::run_shared(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t out_bytes_per_ray,
                               const CallOptions& options, CallStats* stats, bool* send_bytes) {
  const uint64_t n = rays.size();
  const uint64_t answers_at = answers_offset(rays.size_bytes());
  const uint64_t need = answers_at + n * out_bytes_per_ray;
  if (need >= shared_failed_bytes_.load(std::memory_order_relaxed)) {
    *send_bytes = true;
    return Status::Ok();
  }
  auto object = take_object(need);
  if (!object.ok()) {
    // No room in /dev/shm (a container's is 64 MiB by default): this batch
    // and larger ones go as bytes; smaller ones still try.
    uint64_t failed = shared_failed_bytes_.load(std::memory_order_relaxed);
    while (need < failed && !shared_failed_bytes_.compare_exchange_weak(failed, need)) {
    }
    *send_bytes = true;
    return Status::Ok();
  }
  parallel_copy((*object)->data() + kRaysOffset, rays.data(), rays.size_bytes());
  v1::QueryRequest request;
  v1::RayBatch* batch = request.mutable_batch();
  batch->set_layout_version(1);
  batch->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  batch->set_ray_count(n);
  request.set_strict(options.strict);
  request.set_no_reorder(options.no_reorder);
  request.mutable_only_bricks()->Add(options.only_bricks.begin(), options.only_bricks.end());
  v1::SharedPayload* shared = request.mutable_shared();
  shared->set_name((*object)->name());
  shared->set_rays_offset(kRaysOffset);
  shared->set_answers_offset(answers_at);
  shared->set_token((*object)->token());
  grpc::ClientContext context;
  set_deadline(context, options.deadline_seconds);
  Response response;
  const std::string method = method_name(static_cast<const Response*>(nullptr));
  const grpc::Status status = call_unary(*stub_, &context, request, &response);
  // After a failed call the server may still be writing answers into the
  // object: it is not reused (destroying it unlinks it).
  if (!status.ok()) {
    if (status.error_code() == grpc::StatusCode::FAILED_PRECONDITION && shared_refused(context)) {
      stop_using_shared();
      *send_bytes = true;
      return Status::Ok();
    }
    return from_grpc_status(status, method + " on " + address_);
  }
  if (response.layout_version() != 1 || response.ray_count() != n || !response.answers_in_shared() ||
      !payload(response).empty()) {
    return internal_error("the server's reply to a shared-memory " + method + " is malformed: layout " +
                          std::to_string(response.layout_version()) + ", " +
                          std::to_string(response.ray_count()) + " rays (expected " + std::to_string(n) +
                          "), answers_in_shared " + (response.answers_in_shared() ? "true" : "false") + ", " +
                          std::to_string(payload(response).size()) + " payload bytes");
  }
  parallel_copy(out.data(), (*object)->data() + answers_at, n * out_bytes_per_ray);
  give_back_object(std::move(*object));
  add_stats(response.stats(), stats);
  if (options.progress != nullptr) options.progress->advance(n);
  if (stats != nullptr) stats->shared = true;
  return Status::Ok();
}

template <class Response>
Status SceneClient::run(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t out_bytes_per_ray,
                        const CallOptions& options, CallStats* stats) {
  const uint64_t n = rays.size();
  if (n == 0) return Status::Ok();
  // Checked before either path: the shared one answers whole records anyway.
  const uint32_t wire_bytes = wire_bytes_per_ray(static_cast<const Response*>(nullptr), options);
  if (wire_bytes == 0) {
    return invalid_argument("CallOptions::hit_fields " + std::to_string(options.hit_fields) +
                            " is not a HitFields value");
  }
  if (options.chunk_rays == 0 && n >= kSharedMinRays && use_shared_.load(std::memory_order_relaxed)) {
    bool send_bytes = false;
    const Status shared = run_shared<Response>(rays, out, out_bytes_per_ray, options, stats, &send_bytes);
    if (!send_bytes) return shared;
  }
  // Batches of more than kStreamAboveRays rays are streamed in chunks even
  // when they would fit one message: the server traces one chunk while the
  // next and the previous reply are on the wire (1 M rays on the bunny:
  // 0.265 s unary, 0.164 s in 64 k chunks; docs/BENCHMARKS.md).
  constexpr uint64_t kStreamAboveRays = 262144;
  constexpr uint64_t kStreamChunkRays = 65536;
  uint64_t chunk = options.chunk_rays ? std::min(options.chunk_rays, max_chunk_rays_) : max_chunk_rays_;
  if (options.chunk_rays == 0 && n > kStreamAboveRays) chunk = std::min(chunk, kStreamChunkRays);
  const std::string method = method_name(static_cast<const Response*>(nullptr));
  grpc::ClientContext context;
  set_deadline(context, options.deadline_seconds);

  const std::string path = "/" + std::string(v1::SceneQuery::service_full_name()) + "/" + method;
  QueryRequestFields fields;
  fields.strict = options.strict;
  fields.no_reorder = options.no_reorder;
  fields.hit_fields = hit_fields_of(static_cast<const Response*>(nullptr), options);
  fields.only_bricks = options.only_bricks;
  std::vector<uint8_t> scratch;  // packed answers, when fewer fields than a Hit's come
  const auto take = [&](const RawQueryReply& reply, uint64_t first, uint64_t count, uint64_t sequence) {
    return take_reply(reply, count, sequence, wire_bytes, out_bytes_per_ray, fields.hit_fields,
                      out.data() + first * out_bytes_per_ray, scratch, stats, options.progress);
  };

  if (n <= chunk) {
    const RawQueryRequest request = encode_query_request(rays, fields);
    RawQueryReply reply;
    const grpc::Status status = grpc::internal::BlockingUnaryCall<RawQueryRequest, RawQueryReply>(
        channel_.get(),
        grpc::internal::RpcMethod(path.c_str(), grpc::internal::RpcMethod::NORMAL_RPC, channel_), &context,
        request, &reply);
    if (!status.ok()) return from_grpc_status(status, method + " on " + address_);
    return take(reply, 0, n, 0);
  }

  const uint64_t chunks = (n + chunk - 1) / chunk;
  const std::string stream_path = path + "Stream";
  std::unique_ptr<grpc::ClientReaderWriter<RawQueryRequest, RawQueryReply>> stream(
      grpc::internal::ClientReaderWriterFactory<RawQueryRequest, RawQueryReply>::Create(
          channel_.get(),
          grpc::internal::RpcMethod(stream_path.c_str(), grpc::internal::RpcMethod::BIDI_STREAMING, channel_),
          &context));
  // Writing on a second thread keeps the next chunks flowing (up to gRPC's
  // flow-control window) while this thread waits for and copies out replies.
  std::thread writer([&] {
    QueryRequestFields chunk_fields = fields;
    for (uint64_t c = 0; c < chunks; ++c) {
      const uint64_t first = c * chunk;
      chunk_fields.sequence = c;
      if (!stream->Write(
              encode_query_request(rays.subspan(first, std::min(chunk, n - first)), chunk_fields))) {
        return;  // the call ended; Finish() says why
      }
    }
    stream->WritesDone();
  });
  Status reply_status;
  RawQueryReply reply;
  uint64_t received = 0;
  for (; received < chunks; ++received) {
    if (!stream->Read(&reply)) break;
    const uint64_t first = received * chunk;
    reply_status = take(reply, first, std::min(chunk, n - first), received);
    if (!reply_status.ok()) break;
  }
  // A malformed reply: stop the call so the writer wakes up.
  if (!reply_status.ok()) context.TryCancel();
  writer.join();
  const grpc::Status status = stream->Finish();
  if (!reply_status.ok()) return reply_status;
  if (!status.ok()) return from_grpc_status(status, method + "Stream on " + address_);
  if (received != chunks) {
    return internal_error(method + "Stream on " + address_ + ": the server ended the stream after " +
                          std::to_string(received) + " of " + std::to_string(chunks) + " replies");
  }
  return Status::Ok();
}

}  // namespace outcore::client
