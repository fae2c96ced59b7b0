// open_triangle_file: opens an OBJ or PLY file as a TriangleSource, chosen by
// the file's extension (case-insensitive). Unknown extensions are errors,
// never guesses. Inputs that may also be generators (gen:...) are opened by
// core/source/source_factory.h, which sits above both readers and generators.
//
// Thread-safety: free function; safe to call from several threads.
#pragma once

#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// options reach the file readers (memory for vertices, temporary directory).
Expected<std::unique_ptr<TriangleSource>> open_triangle_file(const std::string& path,
                                                             const SourceOptions& options = {});

}  // namespace outcore
