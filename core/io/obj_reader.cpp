#include "core/io/obj_reader.h"
namespace outcore {
// TEMPORARY until the reader lands.
Expected<std::unique_ptr<TriangleSource>> open_obj_file(const std::string& path) { return internal_error(path); }
}  // namespace outcore
