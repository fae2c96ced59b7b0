#include "core/io/file_source.h"

#include <algorithm>
#include <cctype>

#include "core/io/npz_mesh_reader.h"
#include "core/io/obj_reader.h"
#include "core/io/ply_reader.h"

namespace outcore {

namespace {
std::string lower_extension(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return {};
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}
}  // namespace

Expected<std::unique_ptr<TriangleSource>> open_triangle_file(const std::string& path,
                                                             const SourceOptions& options,
                                                             const HeldMemoryLimit& held) {
  const std::string ext = lower_extension(path);
  if (ext == ".obj") return open_obj_file(path, options);
  if (ext == ".ply") return open_ply_file(path, options);
  if (ext == ".npz") return open_npz_mesh_file(path, held);
  // The message names gen: too: a user who mistyped a generator lands here.
  return invalid_argument(
      "input '" + path +
      "': unsupported input kind (expected a .obj, .ply or .npz file, or gen:NAME?key=value&...)");
}

}  // namespace outcore
