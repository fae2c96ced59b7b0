// PLY input: streams the triangles of a PLY file (ascii, binary little- and
// big-endian; `face` lists of any integer types; `tristrips` with -1 restarts).
//
// Thread-safety: the returned source is used by one thread at a time.
#pragma once

#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// Fails with NOT_FOUND if the file cannot be opened and INVALID_ARGUMENT for a
// malformed header. Errors in the body surface from stream() as
// "path:line: what" (ascii) or "path: <element> <index>: what" (binary).
// options bound the memory for vertices; a file with more (by its header)
// resolves its faces out of core on the first stream().
Expected<std::unique_ptr<TriangleSource>> open_ply_file(const std::string& path,
                                                        const SourceOptions& options = {});

}  // namespace outcore
