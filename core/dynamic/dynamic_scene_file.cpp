#include "core/dynamic/dynamic_scene_file.h"

#include <cmath>

#include "core/io/npy.h"
#include "core/io/npz_reader.h"

namespace outcore {
namespace {

using Members = std::map<std::string, std::string>;

Expected<NpyNumbers> array(const Members& members, const std::string& key, const std::string& path) {
  const auto it = members.find(key);
  if (it == members.end()) return invalid_argument(path + ": no array '" + key + "'");
  return decode_numeric_npy(it->second, path + ", array " + key);
}

Status expect_shape(const NpyNumbers& a, std::vector<uint64_t> shape, const std::string& what,
                    const char* expected) {
  if (a.shape.size() != shape.size())
    return invalid_argument(what + " has shape " + npy_shape_text(a.shape) + "; " + expected);
  for (std::size_t d = 0; d < shape.size(); ++d)
    if (shape[d] != 0 && a.shape[d] != shape[d])
      return invalid_argument(what + " has shape " + npy_shape_text(a.shape) + "; " + expected);
  return Status::Ok();
}

Expected<std::vector<uint32_t>> indices(const NpyNumbers& a, const std::string& what) {
  if (!a.integral) return invalid_argument(what + " must be an integer array");
  std::vector<uint32_t> out(a.values.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double v = a.values[i];
    if (!(v >= 0 && v <= 4294967295.0))
      return invalid_argument(what + ": element " + std::to_string(i) + " is " + std::to_string(v) +
                              ", outside 0..4294967295");
    out[i] = static_cast<uint32_t>(v);
  }
  return out;
}

}  // namespace

Expected<DynamicSceneFile> read_dynamic_scene_file(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(const Members members, read_npz(path));
  DynamicSceneFile file;
  std::size_t known = 0;
  for (uint32_t m = 0;; ++m) {
    const std::string prefix = "mesh" + std::to_string(m) + "_";
    if (!members.contains(prefix + "vertices") && !members.contains(prefix + "triangles")) break;
    OUTCORE_ASSIGN_OR_RETURN(const NpyNumbers vertices, array(members, prefix + "vertices", path));
    OUTCORE_RETURN_IF_ERROR(
        expect_shape(vertices, {0, 3}, path + ", array " + prefix + "vertices", "(N, 3) is needed"));
    OUTCORE_ASSIGN_OR_RETURN(const NpyNumbers triangles, array(members, prefix + "triangles", path));
    OUTCORE_RETURN_IF_ERROR(
        expect_shape(triangles, {0, 3}, path + ", array " + prefix + "triangles", "(M, 3) is needed"));
    DynamicSceneFile::Mesh mesh;
    mesh.vertices.assign(vertices.values.begin(), vertices.values.end());
    OUTCORE_ASSIGN_OR_RETURN(mesh.triangles, indices(triangles, path + ", array " + prefix + "triangles"));
    file.meshes.push_back(std::move(mesh));
    known += 2;
  }
  if (file.meshes.empty())
    return invalid_argument(path + ": no meshes (arrays mesh0_vertices, mesh0_triangles)");
  OUTCORE_ASSIGN_OR_RETURN(const NpyNumbers instance_mesh, array(members, "instance_mesh", path));
  OUTCORE_RETURN_IF_ERROR(expect_shape(instance_mesh, {0}, path + ", array instance_mesh", "(K,) is needed"));
  OUTCORE_ASSIGN_OR_RETURN(file.instance_mesh, indices(instance_mesh, path + ", array instance_mesh"));
  for (std::size_t k = 0; k < file.instance_mesh.size(); ++k)
    if (file.instance_mesh[k] >= file.meshes.size())
      return invalid_argument(path + ", array instance_mesh: instance " + std::to_string(k) + " names mesh " +
                              std::to_string(file.instance_mesh[k]) + ", the file has " +
                              std::to_string(file.meshes.size()));
  OUTCORE_ASSIGN_OR_RETURN(const NpyNumbers transforms, array(members, "transforms", path));
  const uint64_t k = file.instance_mesh.size();
  const std::string what = path + ", array transforms";
  if (transforms.shape.size() == 3) {
    OUTCORE_RETURN_IF_ERROR(expect_shape(transforms, {k, 3, 4}, what, "(K, 3, 4) or (F, K, 3, 4) is needed"));
    file.frames = 1;
  } else {
    OUTCORE_RETURN_IF_ERROR(
        expect_shape(transforms, {0, k, 3, 4}, what, "(K, 3, 4) or (F, K, 3, 4) is needed"));
    if (transforms.shape[0] == 0 || transforms.shape[0] > 0xffffffffu)
      return invalid_argument(what + " has no frames");
    file.frames = static_cast<uint32_t>(transforms.shape[0]);
  }
  file.transforms = transforms.values;
  known += 2;
  if (members.size() != known) {
    for (const auto& [key, bytes] : members) {
      const bool mesh_array = key.rfind("mesh", 0) == 0;
      if (key != "instance_mesh" && key != "transforms" && !mesh_array)
        return invalid_argument(path + ": unknown array '" + key +
                                "' (meshN_vertices, meshN_triangles, instance_mesh, transforms)");
    }
    return invalid_argument(path +
                            ": mesh arrays are not numbered 0, 1, 2, ... in pairs (meshN_vertices, "
                            "meshN_triangles)");
  }
  return file;
}

Expected<std::vector<uint32_t>> add_dynamic_scene(const DynamicSceneFile& file, const std::string& path,
                                                  DynamicScene& scene) {
  std::vector<uint32_t> mesh_ids;
  for (std::size_t m = 0; m < file.meshes.size(); ++m) {
    auto added = scene.add_mesh(file.meshes[m].vertices, file.meshes[m].triangles);
    if (!added.ok()) return added.status().with_context(path + ", mesh " + std::to_string(m));
    mesh_ids.push_back(added->id);
  }
  const std::span<const double> frame0 = file.frame_transforms(0);
  std::vector<uint32_t> ids;
  for (std::size_t k = 0; k < file.instance_mesh.size(); ++k) {
    auto added = scene.add_instance(mesh_ids[file.instance_mesh[k]], frame0.subspan(12 * k, 12));
    if (!added.ok())
      return added.status().with_context(path + ", instance " + std::to_string(k) + ", frame 0");
    ids.push_back(added->id);
  }
  return ids;
}

}  // namespace outcore
