// OBJ input: streams the triangles of a Wavefront OBJ file (see obj_reader.cpp
// for the accepted subset and why it is parsed here rather than by tinyobjloader).
//
// Thread-safety: the returned source is used by one thread at a time.
#pragma once

#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// Fails with NOT_FOUND if the file cannot be opened. Parse errors surface from
// stream() as "path:line: what". options bound the memory for vertices; a file
// with more resolves its faces out of core on the first stream().
Expected<std::unique_ptr<TriangleSource>> open_obj_file(const std::string& path,
                                                        const SourceOptions& options = {});

}  // namespace outcore
