// The dynamic scene file of `outcore trace --dynamic FILE.npz`: meshes and
// the per-frame placements of their instances, as NumPy arrays in one .npz
// (numpy.savez or savez_compressed):
//
//   mesh0_vertices   (N, 3) real          the first mesh's vertices
//   mesh0_triangles  (M, 3) integer       its triangles (vertex indices)
//   mesh1_vertices, mesh1_triangles, ...  more meshes, numbered without gaps
//   instance_mesh    (K,) integer         each instance's mesh
//   transforms       (K, 3, 4) or (F, K, 3, 4) real
//                                         each instance's row-major 3x4
//                                         placement, for one or F frames
//
// Instances get geometry ids after the store's inputs, in file order. An
// array missing, misshapen or of another kind, a mesh index out of range, an
// unknown array name: INVALID_ARGUMENT naming the file and the array.
//
// Thread-safety: free functions.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/dynamic/dynamic_scene.h"
#include "core/util/status.h"

namespace outcore {

struct DynamicSceneFile {
  struct Mesh {
    std::vector<float> vertices;      // x, y, z each
    std::vector<uint32_t> triangles;  // a, b, c each
  };
  std::vector<Mesh> meshes;
  std::vector<uint32_t> instance_mesh;
  uint32_t frames = 0;
  std::vector<double> transforms;  // frames x instances x 12

  std::span<const double> frame_transforms(uint32_t frame) const {
    return std::span(transforms)
        .subspan(uint64_t{frame} * instance_mesh.size() * 12, instance_mesh.size() * 12);
  }
};

Expected<DynamicSceneFile> read_dynamic_scene_file(const std::string& path);

// Adds the file's meshes, then its instances at frame 0; returns their
// geometry ids (errors name the file).
Expected<std::vector<uint32_t>> add_dynamic_scene(const DynamicSceneFile& file, const std::string& path,
                                                  DynamicScene& scene);

}  // namespace outcore
