// open_triangle_source: the one place that turns what a user wrote on the
// command line (`model.obj`, `scan.ply`, `gen:city?copies=100`) into a
// TriangleSource: a generator for gen: specs (core/gen), a file reader
// otherwise (core/io/file_source.h). It sits above both so that neither
// depends on the other's factory. read_all_triangles holds a whole input in
// memory, for inputs known to be small (stress scenes, tests, benchmarks).
//
// Thread-safety: free function; safe to call from several threads.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"

namespace outcore {

// options reach the file readers (memory for vertices, temporary directory),
// held the generators and the .npz reader (HeldMemoryLimit, triangle_source.h).
Expected<std::unique_ptr<TriangleSource>> open_triangle_source(const std::string& spec,
                                                               const SourceOptions& options = {},
                                                               const HeldMemoryLimit& held = {});

// Every triangle of `spec`, in the source's order.
Expected<std::vector<Triangle>> read_all_triangles(const std::string& spec);

}  // namespace outcore
