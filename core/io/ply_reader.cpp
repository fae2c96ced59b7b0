#include "core/io/ply_reader.h"
namespace outcore {
// TEMPORARY until the reader lands.
Expected<std::unique_ptr<TriangleSource>> open_ply_file(const std::string& path) { return internal_error(path); }
}  // namespace outcore
