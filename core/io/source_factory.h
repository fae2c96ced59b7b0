// open_triangle_source: the one place that turns what a user wrote on the
// command line (`model.obj`, `scan.ply`, `gen:city?copies=100`) into a
// TriangleSource. Unknown extensions and generators are errors, never guesses.
//
// Thread-safety: free function; safe to call from several threads.
#pragma once

#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// options reach the file readers (memory for vertices, temporary directory).
Expected<std::unique_ptr<TriangleSource>> open_triangle_source(const std::string& spec,
                                                               const SourceOptions& options = {});

}  // namespace outcore
