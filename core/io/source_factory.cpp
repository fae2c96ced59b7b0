#include "core/io/source_factory.h"

#include <algorithm>
#include <cctype>

#include "core/gen/generator_factory.h"
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

Expected<std::unique_ptr<TriangleSource>> open_triangle_source(const std::string& spec,
                                                               const SourceOptions& options) {
  if (spec.rfind("gen:", 0) == 0) return make_generator(spec);
  const std::string ext = lower_extension(spec);
  if (ext == ".obj") return open_obj_file(spec, options);
  if (ext == ".ply") return open_ply_file(spec, options);
  return invalid_argument(
      "input '" + spec +
      "': unsupported input kind (expected a .obj or .ply file, or gen:NAME?key=value&...)");
}

}  // namespace outcore
