// open_triangle_source: the one place that turns what a user wrote on the
// command line (`model.obj`, `scan.ply`, `gen:city?copies=100`) into a
// TriangleSource: a generator for gen: specs (core/gen), a file reader
// otherwise (core/io/file_source.h). It sits above both so that neither
// depends on the other's factory.
//
// Thread-safety: free function; safe to call from several threads.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/io/triangle_source.h"

namespace outcore {

// What a source may hold in memory for its lifetime (gen:city's welded base
// mesh, TriangleSource::held_memory_bytes()); the defaults mean no limit.
struct HeldMemoryLimit {
  uint64_t bytes = 0;  // 0: no limit
  std::string origin;  // where the limit comes from, for messages ("half of --mem-mb 1024")
};

// options reach the file readers (memory for vertices, temporary directory),
// held the generators.
Expected<std::unique_ptr<TriangleSource>> open_triangle_source(const std::string& spec,
                                                               const SourceOptions& options = {},
                                                               const HeldMemoryLimit& held = {});

}  // namespace outcore
