// The dynamic layer's calls (proto "Dynamic geometry"): each checks the
// packed arrays' lengths against their counts, hands them to the engine's
// DynamicScene (which checks the values and changes all or nothing), and
// answers the new version.
#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "server/grpc_status.h"
#include "server/scene_query_service.h"

namespace outcore::server {
namespace {

using Clock = std::chrono::steady_clock;

// `bytes` as `count` records of three 4-byte values (little-endian, as
// this host), copied into aligned storage.
template <typename T>
Expected<std::vector<T>> unpack_triples(const std::string& bytes, uint64_t count, const std::string& field,
                                        const std::string& count_field) {
  static_assert(sizeof(T) == 4);
  if (count > bytes.size() / 12 || bytes.size() != count * 12)
    return invalid_argument(field + " holds " + std::to_string(bytes.size()) + " bytes; " + count_field +
                            " " + std::to_string(count) + " needs " + std::to_string(count * 12) +
                            " (12 each)");
  std::vector<T> values(count * 3);
  if (!values.empty()) std::memcpy(values.data(), bytes.data(), bytes.size());
  return values;
}

}  // namespace

grpc::Status SceneQueryService::AddMesh(grpc::ServerContext* context, const v1::AddMeshRequest* request,
                                        v1::AddMeshResponse* response) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const auto run = [&]() -> Status {
    OUTCORE_ASSIGN_OR_RETURN(
        const std::vector<float> vertices,
        unpack_triples<float>(request->vertices(), request->vertex_count(), "vertices", "vertex_count"));
    OUTCORE_ASSIGN_OR_RETURN(const std::vector<uint32_t> triangles,
                             unpack_triples<uint32_t>(request->triangles(), request->triangle_count(),
                                                      "triangles", "triangle_count"));
    OUTCORE_ASSIGN_OR_RETURN(const DynamicAdded added, engine_.dynamic().add_mesh(vertices, triangles));
    response->set_mesh_id(added.id);
    response->set_version(added.version);
    return Status::Ok();
  };
  return finish(context, "AddMesh", to_grpc_status(run()), 0, start);
}

grpc::Status SceneQueryService::AddInstance(grpc::ServerContext* context,
                                            const v1::AddInstanceRequest* request,
                                            v1::AddInstanceResponse* response) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const auto run = [&]() -> Status {
    const std::vector<double> transform(request->transform().begin(), request->transform().end());
    OUTCORE_ASSIGN_OR_RETURN(const DynamicAdded added,
                             engine_.dynamic().add_instance(request->mesh_id(), transform));
    response->set_geometry_id(added.id);
    response->set_version(added.version);
    return Status::Ok();
  };
  return finish(context, "AddInstance", to_grpc_status(run()), 0, start);
}

grpc::Status SceneQueryService::UpdateTransforms(grpc::ServerContext* context,
                                                 const v1::UpdateTransformsRequest* request,
                                                 v1::DynamicVersion* response) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const std::vector<uint32_t> ids(request->geometry_ids().begin(), request->geometry_ids().end());
  const std::vector<double> transforms(request->transforms().begin(), request->transforms().end());
  auto version = engine_.dynamic().update_transforms(ids, transforms);
  if (version.ok()) response->set_version(*version);
  return finish(context, "UpdateTransforms", to_grpc_status(version.status()), 0, start);
}

grpc::Status SceneQueryService::UpdateVertices(grpc::ServerContext* context,
                                               const v1::UpdateVerticesRequest* request,
                                               v1::DynamicVersion* response) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  const auto run = [&]() -> Status {
    OUTCORE_ASSIGN_OR_RETURN(
        const std::vector<float> vertices,
        unpack_triples<float>(request->vertices(), request->vertex_count(), "vertices", "vertex_count"));
    OUTCORE_ASSIGN_OR_RETURN(const uint64_t version,
                             engine_.dynamic().update_vertices(request->mesh_id(), vertices));
    response->set_version(version);
    return Status::Ok();
  };
  return finish(context, "UpdateVertices", to_grpc_status(run()), 0, start);
}

grpc::Status SceneQueryService::Remove(grpc::ServerContext* context, const v1::RemoveRequest* request,
                                       v1::DynamicVersion* response) {
  const auto start = Clock::now();
  OUTCORE_RETURN_IF_GRPC_ERROR(authorize(*context));
  auto version = engine_.dynamic().remove(request->geometry_id());
  if (version.ok()) response->set_version(*version);
  return finish(context, "Remove", to_grpc_status(version.status()), 0, start);
}

}  // namespace outcore::server
