#include "core/dynamic/dynamic_scene.h"

#include <algorithm>
#include <string>
#include <unordered_set>

namespace outcore {
namespace {

constexpr double kFloatEpsilon = 1.0 / (1 << 23);

Expected<DynamicInstance> place(uint32_t geometry_id, uint32_t mesh_id, const DynamicMesh& mesh,
                                std::span<const double> rows, const std::string& what) {
  OUTCORE_ASSIGN_OR_RETURN(AffineTransform to_world, AffineTransform::from_rows(rows, what));
  DynamicInstance instance;
  instance.geometry_id = geometry_id;
  instance.mesh_id = mesh_id;
  instance.to_world = to_world;
  instance.to_object = to_world.inverse();
  instance.world_box = to_world.world_box(mesh.bounds());
  // The ray's origin and direction are rounded to float in the object frame
  // (an ulp each, up to the condition number seen back in the world).
  instance.slack = 4 * kFloatEpsilon * to_world.condition_number();
  return instance;
}

// The instance's world box after its mesh changed.
void replace_mesh_box(DynamicInstance& instance, const DynamicMesh& mesh) {
  instance.world_box = instance.to_world.world_box(mesh.bounds());
}

}  // namespace

DynamicScene::DynamicScene(uint32_t first_geometry_id, DynamicTopLevel top_level)
    : first_geometry_id_(first_geometry_id), next_geometry_id_(first_geometry_id) {
  auto empty = std::make_shared<DynamicSnapshot>();
  empty->top_kind = top_level;
  versions_.push_back(std::move(empty));
}

std::shared_ptr<const DynamicSnapshot> DynamicScene::latest() const {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  return versions_.back();
}

Expected<std::shared_ptr<const DynamicSnapshot>> DynamicScene::at(uint64_t version) const {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  const uint64_t oldest = versions_.front()->version, newest = versions_.back()->version;
  if (version > newest)
    return not_found("dynamic scene version " + std::to_string(version) +
                     " does not exist yet (latest: " + std::to_string(newest) + ")");
  if (version < oldest)
    return not_found("dynamic scene version " + std::to_string(version) +
                     " is no longer kept (oldest kept: " + std::to_string(oldest) +
                     ", latest: " + std::to_string(newest) + ")");
  return versions_[version - oldest];
}

DynamicScene::Counters DynamicScene::counters() const {
  std::lock_guard<std::mutex> lock(change_mutex_);
  return counters_;
}

std::shared_ptr<DynamicSnapshot> DynamicScene::copy_of_latest() const {
  return std::make_shared<DynamicSnapshot>(*latest());
}

uint64_t DynamicScene::publish(std::shared_ptr<DynamicSnapshot> next) {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  next->version = versions_.back()->version + 1;
  versions_.push_back(std::move(next));
  while (versions_.size() > kKeptVersions) versions_.pop_front();
  return versions_.back()->version;
}

Status DynamicScene::check_mesh_id(uint32_t mesh_id, const DynamicSnapshot& s, const char* operation) const {
  if (mesh_id >= s.meshes.size())
    return not_found(std::string(operation) + ": no mesh " + std::to_string(mesh_id) + " (the scene has " +
                     std::to_string(s.meshes.size()) + " meshes)");
  return Status::Ok();
}

Expected<DynamicAdded> DynamicScene::add_mesh(std::span<const float> vertices,
                                              std::span<const uint32_t> triangles) {
  std::lock_guard<std::mutex> lock(change_mutex_);
  std::shared_ptr<DynamicSnapshot> next = copy_of_latest();
  const auto mesh_id = static_cast<uint32_t>(next->meshes.size());
  OUTCORE_ASSIGN_OR_RETURN(
      std::shared_ptr<const DynamicMesh> mesh,
      DynamicMesh::create(vertices, triangles, "add_mesh (mesh " + std::to_string(mesh_id) + ")"));
  next->meshes.push_back(std::move(mesh));
  return DynamicAdded{mesh_id, publish(std::move(next))};
}

Expected<DynamicAdded> DynamicScene::add_instance(uint32_t mesh_id, std::span<const double> transform) {
  std::lock_guard<std::mutex> lock(change_mutex_);
  std::shared_ptr<DynamicSnapshot> next = copy_of_latest();
  OUTCORE_RETURN_IF_ERROR(check_mesh_id(mesh_id, *next, "add_instance"));
  if (next_geometry_id_ == kInvalidId)
    return resource_exhausted("add_instance: no geometry ids left (they run to 4294967294)");
  const uint32_t id = next_geometry_id_;
  OUTCORE_ASSIGN_OR_RETURN(DynamicInstance instance,
                           place(id, mesh_id, *next->meshes[mesh_id], transform,
                                 "add_instance (mesh " + std::to_string(mesh_id) + ")"));
  next->instances.push_back(instance);  // ids only grow: the order by id holds
  build_dynamic_top_level(*next);
  ++counters_.top_rebuilds;
  ++next_geometry_id_;
  return DynamicAdded{id, publish(std::move(next))};
}

Expected<uint64_t> DynamicScene::update_transforms(std::span<const uint32_t> geometry_ids,
                                                   std::span<const double> transforms) {
  std::lock_guard<std::mutex> lock(change_mutex_);
  if (transforms.size() != geometry_ids.size() * 12)
    return invalid_argument("update_transforms: " + std::to_string(geometry_ids.size()) + " ids need " +
                            std::to_string(geometry_ids.size() * 12) + " numbers (12 each), got " +
                            std::to_string(transforms.size()));
  std::shared_ptr<DynamicSnapshot> next = copy_of_latest();
  std::unordered_set<uint32_t> seen;
  for (std::size_t k = 0; k < geometry_ids.size(); ++k) {
    const uint32_t id = geometry_ids[k];
    // Named only on an error: an update may carry tens of thousands of entries.
    const auto entry = [&] {
      return "update_transforms (entry " + std::to_string(k) + ", geometry " + std::to_string(id) + ")";
    };
    DynamicInstance* found = next->find(id);
    if (found == nullptr) return not_found(entry() + ": no such dynamic instance");
    if (!seen.insert(id).second) return invalid_argument(entry() + ": the id appears twice");
    auto placed =
        place(id, found->mesh_id, *next->meshes[found->mesh_id], transforms.subspan(12 * k, 12), "transform");
    if (!placed.ok()) return placed.status().with_context(entry());
    *found = *placed;
  }
  if (refit_dynamic_top_level(*next)) {
    ++counters_.top_rebuilds;
  } else {
    ++counters_.top_refits;
  }
  return publish(std::move(next));
}

Expected<uint64_t> DynamicScene::update_vertices(uint32_t mesh_id, std::span<const float> vertices) {
  std::lock_guard<std::mutex> lock(change_mutex_);
  std::shared_ptr<DynamicSnapshot> next = copy_of_latest();
  OUTCORE_RETURN_IF_ERROR(check_mesh_id(mesh_id, *next, "update_vertices"));
  OUTCORE_ASSIGN_OR_RETURN(
      std::shared_ptr<const DynamicMesh> moved,
      next->meshes[mesh_id]->moved(vertices, "update_vertices (mesh " + std::to_string(mesh_id) + ")"));
  ++(moved->rebuilt() ? counters_.mesh_rebuilds : counters_.mesh_refits);
  next->meshes[mesh_id] = moved;
  bool placed = false;
  for (DynamicInstance& instance : next->instances) {
    if (instance.mesh_id != mesh_id) continue;
    replace_mesh_box(instance, *moved);
    placed = true;
  }
  if (placed) ++(refit_dynamic_top_level(*next) ? counters_.top_rebuilds : counters_.top_refits);
  return publish(std::move(next));
}

Expected<uint64_t> DynamicScene::remove(uint32_t geometry_id) {
  std::lock_guard<std::mutex> lock(change_mutex_);
  std::shared_ptr<DynamicSnapshot> next = copy_of_latest();
  const DynamicInstance* found = next->find(geometry_id);
  if (found == nullptr)
    return not_found("remove: no dynamic instance with geometry id " + std::to_string(geometry_id));
  next->instances.erase(next->instances.begin() + (found - next->instances.data()));
  build_dynamic_top_level(*next);
  ++counters_.top_rebuilds;
  return publish(std::move(next));
}

}  // namespace outcore
