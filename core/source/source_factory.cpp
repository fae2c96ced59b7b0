#include "core/source/source_factory.h"

#include "core/gen/generator_factory.h"
#include "core/io/file_source.h"

namespace outcore {

Expected<std::unique_ptr<TriangleSource>> open_triangle_source(const std::string& spec,
                                                               const SourceOptions& options,
                                                               const HeldMemoryLimit& held) {
  if (spec.starts_with("gen:")) {
    GeneratorOptions generator_options;
    generator_options.mesh_memory_bytes = held.bytes;
    generator_options.mesh_memory_origin = held.origin;
    return make_generator(spec, generator_options);
  }
  return open_triangle_file(spec, options, held);
}

Expected<std::vector<Triangle>> read_all_triangles(const std::string& spec) {
  OUTCORE_ASSIGN_OR_RETURN(auto source, open_triangle_source(spec));
  return read_all(*source);
}

}  // namespace outcore
