#include "core/dynamic/dynamic_mesh.h"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <cstring>

#include "core/accel/bvh/binned_sah_builder.h"
#include "core/accel/bvh/wide_bvh_collapse.h"
#include "core/accel/bvh/wide_bvh_refit.h"
#include "core/geometry/triangle.h"
#include "core/ray/ray_types.h"
#include "core/store/brick_data.h"

namespace outcore {
namespace {

Expected<std::vector<Vec3f>> read_vertices(std::span<const float> xyz, const std::string& what) {
  if (xyz.size() % 3 != 0)
    return invalid_argument(what + ": vertices hold " + std::to_string(xyz.size()) +
                            " numbers, not a multiple of 3 (x, y, z per vertex)");
  if (xyz.size() / 3 > 0xffffffffu) return invalid_argument(what + ": more than 4294967295 vertices");
  std::vector<Vec3f> vertices(xyz.size() / 3);
  for (std::size_t v = 0; v < vertices.size(); ++v) {
    vertices[v] = {xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]};
    if (!is_finite(vertices[v]))
      return invalid_argument(what + ": vertex " + std::to_string(v) + " is not finite");
  }
  return vertices;
}

Triangle triangle_of(const MeshTopology& topology, std::span<const Vec3f> vertices, uint32_t t) {
  const auto& [a, b, c] = topology.triangles[t];
  return {vertices[a], vertices[b], vertices[c]};
}

// Writes each used slot's triangle from the vertices (its primitive id is
// the mesh triangle); unused slots keep zero vertices, as built.
void write_packet(TrianglePacket& packet, const MeshTopology& topology, std::span<const Vec3f> vertices) {
  for (uint32_t lane = 0; lane < kPacketLanes; ++lane) {
    if (packet.primitive_id[lane] == kInvalidId) continue;
    const Triangle tri = triangle_of(topology, vertices, packet.primitive_id[lane]);
    const Vec3f corners[3] = {tri.v0, tri.v1, tri.v2};
    for (int v = 0; v < 3; ++v)
      for (int axis = 0; axis < 3; ++axis) packet.coord[3 * v + axis][lane] = corners[v][axis];
  }
}

// A fresh array of a large tree is most of a refit's time in page faults
// (one a 4 KiB page); asking for transparent huge pages before it is first
// touched makes them one a 2 MiB page where the kernel allows it (a hint:
// nothing changes where it does not).
template <typename T>
void resize_on_huge_pages(std::vector<T>& v, std::size_t n) {
  v.reserve(n);
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  const auto begin = reinterpret_cast<uintptr_t>(v.data());
  const uintptr_t first = (begin + kHuge - 1) & ~(kHuge - 1), last = (begin + n * sizeof(T)) & ~(kHuge - 1);
  if (last > first) madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE);
  v.resize(n);
}

// `from`'s tree with its packets' triangles taken from the vertices: the
// nodes copied, each packet's ids copied and its coordinates written, in
// parallel (one pass over the new packets).
WideBvh moved_tree(const WideBvh& from, const MeshTopology& topology, std::span<const Vec3f> vertices) {
  WideBvh tree;
  resize_on_huge_pages(tree.nodes, from.nodes.size());
  resize_on_huge_pages(tree.packets, from.packets.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, from.nodes.size(), 4096), [&](const auto& range) {
    std::memcpy(&tree.nodes[range.begin()], &from.nodes[range.begin()], range.size() * sizeof(WideBvhNode));
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, from.packets.size(), 1024), [&](const auto& range) {
    for (std::size_t p = range.begin(); p != range.end(); ++p) {
      TrianglePacket& packet = tree.packets[p];
      std::memcpy(packet.geometry_id, from.packets[p].geometry_id, sizeof(packet.geometry_id));
      std::memcpy(packet.primitive_id, from.packets[p].primitive_id, sizeof(packet.primitive_id));
      write_packet(packet, topology, vertices);
    }
  });
  return tree;
}

Aabb bounds_of(std::span<const Vec3f> vertices) {
  Aabb box;
  for (const Vec3f& v : vertices) box.extend(v);
  return box;
}

}  // namespace

std::shared_ptr<const DynamicMesh> DynamicMesh::build(std::shared_ptr<const MeshTopology> topology,
                                                      std::vector<Vec3f> vertices) {
  const std::size_t n = topology->triangles.size();
  std::vector<Triangle> triangles(n);
  std::vector<TriangleId> ids(n);
  for (std::size_t t = 0; t < n; ++t) {
    triangles[t] = triangle_of(*topology, vertices, static_cast<uint32_t>(t));
    ids[t] = {0, static_cast<uint32_t>(t)};
  }
  const BinnedSahBuilder::Result binary = BinnedSahBuilder::build(triangles, BinnedSahBuilder::Config{});
  std::shared_ptr<DynamicMesh> mesh(new DynamicMesh());
  mesh->tree_ = WideBvhCollapser::collapse(binary.nodes, binary.order, triangles, ids).tree;
  mesh->topology_ = std::move(topology);
  mesh->bounds_ = bounds_of(vertices);
  mesh->vertices_ = std::move(vertices);
  mesh->sah_cost_ = mesh->built_sah_cost_ = wide_bvh_sah_cost(mesh->tree_.nodes);
  mesh->rebuilt_ = true;
  return mesh;
}

Expected<std::shared_ptr<const DynamicMesh>> DynamicMesh::create(std::span<const float> vertices,
                                                                 std::span<const uint32_t> triangles,
                                                                 const std::string& what) {
  OUTCORE_ASSIGN_OR_RETURN(std::vector<Vec3f> points, read_vertices(vertices, what));
  if (triangles.size() % 3 != 0)
    return invalid_argument(what + ": triangles hold " + std::to_string(triangles.size()) +
                            " indices, not a multiple of 3");
  if (triangles.empty()) return invalid_argument(what + ": the mesh has no triangles");
  if (triangles.size() / 3 > kMaxTriangles)
    return invalid_argument(what + ": more than " + std::to_string(kMaxTriangles) + " triangles");
  auto topology = std::make_shared<MeshTopology>();
  topology->vertex_count = static_cast<uint32_t>(points.size());
  topology->triangles.resize(triangles.size() / 3);
  for (std::size_t t = 0; t < topology->triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t index = triangles[3 * t + k];
      if (index >= points.size())
        return invalid_argument(what + ": triangle " + std::to_string(t) + " names vertex " +
                                std::to_string(index) + ", beyond the " + std::to_string(points.size()) +
                                " vertices");
      topology->triangles[t][k] = index;
    }
  }
  return build(std::move(topology), std::move(points));
}

Expected<std::shared_ptr<const DynamicMesh>> DynamicMesh::moved(std::span<const float> vertices,
                                                                const std::string& what) const {
  OUTCORE_ASSIGN_OR_RETURN(std::vector<Vec3f> points, read_vertices(vertices, what));
  if (points.size() != topology_->vertex_count)
    return invalid_argument(what + ": " + std::to_string(points.size()) + " vertices given, the mesh has " +
                            std::to_string(topology_->vertex_count) + " (its topology is fixed)");
  std::shared_ptr<DynamicMesh> mesh(new DynamicMesh());
  mesh->tree_ = moved_tree(tree_, *topology_, points);
  refit_wide_bvh(mesh->tree_);
  mesh->sah_cost_ = wide_bvh_sah_cost(mesh->tree_.nodes);
  if (mesh->sah_cost_ > kRebuildRatio * built_sah_cost_) return build(topology_, std::move(points));
  mesh->topology_ = topology_;
  mesh->bounds_ = bounds_of(points);
  mesh->vertices_ = std::move(points);
  mesh->built_sah_cost_ = built_sah_cost_;
  mesh->rebuilt_ = false;
  return std::shared_ptr<const DynamicMesh>(std::move(mesh));
}

std::shared_ptr<const DynamicMesh> DynamicMesh::rebuilt_fresh() const {
  return build(topology_, vertices_);
}

uint64_t DynamicMesh::memory_bytes() const {
  return sizeof(*this) + tree_.memory_bytes() + vertices_.capacity() * sizeof(Vec3f);
}

}  // namespace outcore
