// Every hit (CountIntersections, ListIntersections) and point queries
// (QueryPoints): the request checked as the ray calls check theirs, the
// engine's answer packed in the layouts the proto names.
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "core/query/point_queries.h"
#include "server/grpc_status.h"
#include "server/scene_query_service.h"
#include "server/wire_mapping.h"

namespace outcore::server {
namespace {

using Clock = std::chrono::steady_clock;

// CLOSEST's record (proto "Point queries").
struct ClosestRecord {
  float x, y, z;
  uint32_t geometry_id, primitive_id;
  float u, v;
  float nx, ny, nz;
  float distance;
};
static_assert(sizeof(ClosestRecord) == 44);

uint64_t answer_bytes(v1::PointQueryKind kind) {
  switch (kind) {
    case v1::POINT_QUERY_CLOSEST: return sizeof(ClosestRecord);
    case v1::POINT_QUERY_DISTANCE:
    case v1::POINT_QUERY_SIGNED_DISTANCE: return sizeof(float);
    case v1::POINT_QUERY_OCCUPANCY: return 1;
    default: return 0;
  }
}

float distance_of(const ClosestPoint& point) {
  return static_cast<float>(std::sqrt(point.distance_squared));
}

// The request's points, or the error naming what is wrong.
Expected<std::vector<Vec3f>> decode_points(const v1::PointRequest& request, uint64_t max_message_bytes) {
  if (request.layout_version() != 1)
    return invalid_argument("request.layout_version is " + std::to_string(request.layout_version()) +
                            "; this server reads layout 1");
  const uint64_t per_point = answer_bytes(request.kind());
  if (per_point == 0)
    return invalid_argument("request.kind " + std::to_string(static_cast<int>(request.kind())) +
                            " is not a point query (CLOSEST, DISTANCE, SIGNED_DISTANCE, OCCUPANCY)");
  const uint64_t n = request.point_count();
  if (n > request.points().size() / 12 || request.points().size() != n * 12)
    return invalid_argument("request.points holds " + std::to_string(request.points().size()) +
                            " bytes; point_count " + std::to_string(n) + " needs " + std::to_string(n * 12) +
                            " (12 each)");
  if (n * per_point + kReplyOverheadBytes > max_message_bytes)
    return resource_exhausted(
        "the reply to " + std::to_string(n) + " points would take about " + std::to_string(n * per_point) +
        " bytes, over the server's max message size of " + std::to_string(max_message_bytes) +
        " bytes (--max-message-mb); send fewer points");
  std::vector<Vec3f> points(n);
  if (n > 0) std::memcpy(static_cast<void*>(points.data()), request.points().data(), n * 12);
  return points;
}

// Packs the answers of `kind` into `out`.
void pack_points(v1::PointQueryKind kind, const std::vector<ClosestPoint>& closest,
                 const std::vector<uint8_t>& inside, std::string& out) {
  const std::size_t n = std::max(closest.size(), inside.size());
  out.resize(n * answer_bytes(kind));
  for (std::size_t i = 0; i < n; ++i) {
    if (kind == v1::POINT_QUERY_OCCUPANCY) {
      out[i] = static_cast<char>(inside[i]);
      continue;
    }
    const ClosestPoint& c = closest[i];
    float distance = c.found() ? distance_of(c) : std::numeric_limits<float>::infinity();
    if (kind == v1::POINT_QUERY_SIGNED_DISTANCE && inside[i] != 0) distance = -distance;
    if (kind == v1::POINT_QUERY_CLOSEST) {
      const ClosestRecord record{c.point.x, c.point.y,  c.point.z,  c.geometry_id, c.primitive_id, c.u,
                                 c.v,       c.normal.x, c.normal.y, c.normal.z,    distance};
      std::memcpy(out.data() + i * sizeof(record), &record, sizeof(record));
    } else {
      std::memcpy(out.data() + i * sizeof(float), &distance, sizeof(float));
    }
  }
}

}  // namespace

template <class Run>
grpc::Status SceneQueryService::answer_once_wanted(grpc::ServerContext* context, const char* method,
                                                   uint64_t items, const Run& run) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const grpc::Status wanted = check_still_wanted(context, "request", items);
  if (!wanted.ok()) return finish(context, method, wanted, items, start);
  return finish(context, method, to_grpc_status(run()), items, start);
}

Status SceneQueryService::every_hit(const v1::QueryRequest& request, std::vector<uint32_t>& counts,
                                    std::vector<RayHitRecord>* records, QueryStats& stats) {
  // Shared payloads are answered by answer_shared and answer_shared_list.
  assert(!request.has_shared());
  const BatchPosition position;
  std::vector<Ray> widened;
  OUTCORE_ASSIGN_OR_RETURN(const std::span<const Ray> rays,
                           check_request<QueryKind::kAllHits>(request, position, widened));
  OUTCORE_ASSIGN_OR_RETURN(auto dynamic, dynamic_for(request));
  counts.assign(rays.size(), 0);
  OUTCORE_RETURN_IF_ERROR(engine_.all_hits(rays, counts, records, options_of(request, dynamic), &stats));
  counters_.add_answered(stats);
  return Status::Ok();
}

grpc::Status SceneQueryService::CountIntersections(grpc::ServerContext* context,
                                                   const v1::QueryRequest* request,
                                                   v1::CountResponse* response) {
  if (request->has_shared()) {
    const auto start = Clock::now();
    OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
    return finish(context, "CountIntersections",
                  answer_shared<QueryKind::kAllHits>(context, *request, response),
                  request->batch().ray_count(), start);
  }
  const auto run = [&]() -> Status {
    std::vector<uint32_t> counts;
    QueryStats stats;
    OUTCORE_RETURN_IF_ERROR(every_hit(*request, counts, nullptr, stats));
    response->set_layout_version(1);
    response->set_ray_count(counts.size());
    response->mutable_counts()->assign(reinterpret_cast<const char*>(counts.data()), counts.size() * 4);
    wire::to_wire(stats, response->mutable_stats());
    return Status::Ok();
  };
  return answer_once_wanted(context, "CountIntersections", request->batch().ray_count(), run);
}

grpc::Status SceneQueryService::ListIntersections(grpc::ServerContext* context,
                                                  const v1::QueryRequest* request,
                                                  v1::ListResponse* response) {
  if (request->has_shared()) {
    const auto start = Clock::now();
    OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
    return finish(context, "ListIntersections", answer_shared_list(context, *request, response),
                  request->batch().ray_count(), start);
  }
  const auto run = [&]() -> Status {
    std::vector<uint32_t> counts;
    std::vector<RayHitRecord> records;
    QueryStats stats;
    OUTCORE_RETURN_IF_ERROR(every_hit(*request, counts, &records, stats));
    response->set_layout_version(1);
    response->set_ray_count(counts.size());
    wire::to_wire(stats, response->mutable_stats());
    return pack_list_reply(counts, records, response);
  };
  return answer_once_wanted(context, "ListIntersections", request->batch().ray_count(), run);
}

Status SceneQueryService::pack_list_reply(std::span<const uint32_t> counts,
                                          const std::vector<RayHitRecord>& records,
                                          v1::ListResponse* response) const {
  const uint64_t bytes = counts.size() * 4 + records.size() * sizeof(Hit) + kReplyOverheadBytes;
  if (bytes > options_.max_message_bytes)
    return resource_exhausted("request: the list of " + std::to_string(records.size()) + " hits on " +
                              std::to_string(counts.size()) + " rays would take about " +
                              std::to_string(bytes) + " bytes, over the server's max message size of " +
                              std::to_string(options_.max_message_bytes) +
                              " bytes (--max-message-mb); send fewer rays per message");
  response->mutable_counts()->assign(reinterpret_cast<const char*>(counts.data()), counts.size() * 4);
  response->set_hit_count(records.size());
  std::string* hits = response->mutable_hits();
  hits->resize(records.size() * sizeof(Hit));
  pack_hit_records(records, hits->data());
  return Status::Ok();
}

grpc::Status SceneQueryService::QueryPoints(grpc::ServerContext* context, const v1::PointRequest* request,
                                            v1::PointResponse* response) {
  const auto run = [&]() -> Status {
    OUTCORE_ASSIGN_OR_RETURN(const std::vector<Vec3f> points,
                             decode_points(*request, options_.max_message_bytes));
    QueryOptions options;
    options.strict = request->strict();
    const v1::PointQueryKind kind = request->kind();
    std::vector<ClosestPoint> closest;
    std::vector<uint8_t> inside;
    QueryStats stats;
    if (kind != v1::POINT_QUERY_OCCUPANCY) {
      closest.resize(points.size());
      OUTCORE_RETURN_IF_ERROR(engine_.closest_points(points, closest, options, &stats));
    }
    if (kind == v1::POINT_QUERY_OCCUPANCY || kind == v1::POINT_QUERY_SIGNED_DISTANCE) {
      inside.resize(points.size());
      QueryStats parity_stats;
      OUTCORE_RETURN_IF_ERROR(engine_.occupancy(points, inside, options, &parity_stats));
      stats.add(parity_stats);
    }
    counters_.add_answered(stats);
    response->set_layout_version(1);
    response->set_point_count(points.size());
    pack_points(kind, closest, inside, *response->mutable_answers());
    wire::to_wire(stats, response->mutable_stats());
    return Status::Ok();
  };
  return answer_once_wanted(context, "QueryPoints", request->point_count(), run);
}

}  // namespace outcore::server
