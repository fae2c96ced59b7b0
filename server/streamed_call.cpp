// The streamed calls (IntersectStream, OccludedStream): the handler thread
// reads and checks chunks, a tracer answers the chunks that queued up with one
// engine call per group, a writer sends the replies in order
// (stream_pipeline.h).
//
// Thread-safety: as the service's handlers (scene_query_service.h); each
// stream's three threads share only its pipeline.
#include <grpcpp/grpcpp.h>
#include <grpcpp/support/byte_buffer.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <span>
#include <string>

#include "server/grpc_status.h"
#include "server/scene_query_service.h"
#include "server/stream_pipeline.h"
#include "server/wire_mapping.h"

namespace outcore::server {

namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

Status SceneQueryService::settle_stream_chunk(const v1::QueryRequest& request, const BatchPosition& position,
                                              StreamSettings& stream) const {
  // A group of chunks is traced and packed as its first chunk asks, so the
  // whole stream has the fields and the part of the scene of its first chunk.
  if (position.chunk == 0) {
    stream.hit_fields = request.hit_fields();
    stream.only_bricks.assign(request.only_bricks().begin(), request.only_bricks().end());
  } else if (request.hit_fields() != stream.hit_fields) {
    return invalid_argument(where(position) + " asks for hit_fields " + std::to_string(request.hit_fields()) +
                            ", the stream's are " + std::to_string(stream.hit_fields) +
                            " (one set of fields a stream)");
  } else if (!std::equal(request.only_bricks().begin(), request.only_bricks().end(),
                         stream.only_bricks.begin(), stream.only_bricks.end())) {
    return invalid_argument(where(position) + " names other only_bricks than the stream's first chunk (" +
                            std::to_string(stream.only_bricks.size()) + " bricks; one part a stream)");
  }
  // The whole stream sees one version of the dynamic layer: the one its
  // first chunk names (or the latest then); later chunks may only repeat it.
  if (stream.dynamic == nullptr) {
    auto dynamic = dynamic_for(request);
    if (!dynamic.ok()) return dynamic.status().with_context(where(position) + ".dynamic_version");
    stream.dynamic = *dynamic;
  } else if (request.has_dynamic_version() && request.dynamic_version() != stream.dynamic->version) {
    return invalid_argument(where(position) + " names dynamic version " +
                            std::to_string(request.dynamic_version()) + ", the stream traces version " +
                            std::to_string(stream.dynamic->version) + " (one version a stream)");
  }
  return Status::Ok();
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::answer_group(grpc::ServerContext* context,
                                             std::span<const std::unique_ptr<StreamChunk>> group,
                                             CallBuffers* buffers,
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
    payload->resize(n * reply_bytes_per_ray<kKind>(first.request));
    status = trace<kKind>(first.rays, reinterpret_cast<uint8_t*>(payload->data()), first.request,
                          first.dynamic, &stats);
  } else {
    // One engine call for the whole group: its rays gathered into one batch,
    // its answers split into the chunks' replies (two copies, far cheaper
    // than tracing the chunks one by one; see stream_pipeline.h).
    buffers->rays.resize(n);
    buffers->answers.resize(n * reply_bytes_per_ray<kKind>(first.request));
    uint64_t at = 0;
    for (const auto& chunk : group) {
      if (!chunk->rays.empty()) std::memcpy(&buffers->rays[at], chunk->rays.data(), chunk->rays.size_bytes());
      at += chunk->rays.size();
    }
    status = trace<kKind>(buffers->rays, reinterpret_cast<uint8_t*>(buffers->answers.data()), first.request,
                          first.dynamic, &stats);
    if (status.ok()) {
      at = 0;
      for (size_t i = 0; i < group.size(); ++i) {
        const uint64_t bytes = group[i]->rays.size() * reply_bytes_per_ray<kKind>(first.request);
        Traits::payload(replies[i].get())
            ->assign(reinterpret_cast<const char*>(buffers->answers.data()) + at, bytes);
        at += bytes;
      }
    }
  }
  if (!status.ok()) return to_grpc_status(status.with_context(where(first.position)));
  for (size_t i = 0; i < group.size(); ++i) {
    Response* reply = replies[i].get();
    set_reply_header(reply, group[i]->rays.size(), group[i]->request.sequence());
    reply->set_dynamic_version(first.dynamic->version);
    if constexpr (kKind == QueryKind::kClosestHit) reply->set_hit_fields(first.request.hit_fields());
    if (i + 1 == group.size()) {
      // The engine call's figures go with the group's last reply; the others
      // count only their own rays (the stream's sums stay exact).
      wire::to_wire(stats, reply->mutable_stats());
      reply->mutable_stats()->set_rays(group[i]->rays.size());
    } else {
      reply->mutable_stats()->set_rays(group[i]->rays.size());
    }
  }
  return grpc::Status::OK;
}

template <QueryKind kKind, class Response>
grpc::Status SceneQueryService::serve_stream(grpc::ServerContext* context,
                                             grpc::ServerReaderWriter<Response, grpc::ByteBuffer>* stream) {
  using Traits = KindTraits<kKind>;
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const auto stream_start = Clock::now();
  StreamPipeline<Response, grpc::ServerReaderWriter<Response, grpc::ByteBuffer>> pipeline(
      stream, options_.max_group_rays, std::chrono::milliseconds(options_.gather_wait_ms));
  // The tracer's first error; read once the tracer has been joined.
  grpc::Status tracer_status = grpc::Status::OK;
  pipeline.start([&] {
    typename StreamPipeline<Response>::Chunks group;
    typename StreamPipeline<Response>::Replies replies;
    // Taken from the pool at the first group of several chunks (a single
    // chunk is traced in place) and kept for the stream's later groups.
    ReusePool<CallBuffers>::Lease buffers;
    while (pipeline.take_group(group)) {
      const auto start = Clock::now();
      if (!pipeline.acquire_replies(group.size(), replies)) break;
      if (group.size() > 1 && buffers.get() == nullptr) buffers = call_buffers_.take();
      const grpc::Status status = answer_group<kKind, Response>(context, group, buffers.get(), replies);
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
  StreamSettings settings;
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
    const Status settled = settle_stream_chunk(chunk->request, position, settings);
    if (!settled.ok()) {
      status = finish(context, Traits::kStream, to_grpc_status(settled), chunk->request.batch().ray_count(),
                      start);
      break;
    }
    chunk->dynamic = settings.dynamic;
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

template grpc::Status SceneQueryService::serve_stream<QueryKind::kClosestHit, v1::IntersectResponse>(
    grpc::ServerContext*, grpc::ServerReaderWriter<v1::IntersectResponse, grpc::ByteBuffer>*);
template grpc::Status SceneQueryService::serve_stream<QueryKind::kAnyHit, v1::OccludedResponse>(
    grpc::ServerContext*, grpc::ServerReaderWriter<v1::OccludedResponse, grpc::ByteBuffer>*);

}  // namespace outcore::server
