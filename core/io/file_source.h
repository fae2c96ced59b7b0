// open_triangle_file: opens an OBJ, PLY or .npz (mesh arrays) file as a
// TriangleSource, chosen by the file's extension (case-insensitive). Unknown extensions are errors,
// never guesses. Inputs that may also be generators (gen:...) are opened by
// core/source/source_factory.h, which sits above both readers and generators.
//
// Thread-safety: free function; safe to call from several threads.
#pragma once

#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// options reach the OBJ and PLY readers (memory for vertices, temporary
// directory), held the .npz reader (which holds its mesh, npz_mesh_reader.h).
Expected<std::unique_ptr<TriangleSource>> open_triangle_file(const std::string& path,
                                                             const SourceOptions& options = {},
                                                             const HeldMemoryLimit& held = {});

}  // namespace outcore
