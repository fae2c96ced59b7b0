// Procedural scene generators, addressed as `gen:NAME?key=value&...` wherever a
// file is accepted (syntax: core/gen/gen_spec.h; generators: city, sphere,
// stadium, terrain, torus, each documented in core/gen/NAME_generator.h).
// Every generator streams (memory independent of its size) and is
// deterministic for a given spec (seeded). Unknown names and unknown or
// out-of-range parameters are errors that name the parameter.
//
// Thread-safety: the returned source is used by one thread at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/gen/generator.h"
#include "core/io/triangle_source.h"

namespace outcore {

// What a generator that holds a mesh in memory (gen:city's base) may hold;
// the defaults mean no limit.
struct GeneratorOptions {
  // Most bytes for gen:city's welded base mesh and the table that welds it;
  // 0: no limit. Checked before reading when the base's triangle count is
  // known (a generator), and as it is read otherwise.
  uint64_t mesh_memory_bytes = 0;
  // Where the limit comes from, for messages ("half of --mem-mb 1024").
  std::string mesh_memory_origin;
};

// spec starts with "gen:".
Expected<std::unique_ptr<TriangleSource>> make_generator(const std::string& spec,
                                                         const GeneratorOptions& options = {});

// The same, as a Generator, which also knows its exact triangle_count().
Expected<std::unique_ptr<Generator>> make_typed_generator(const std::string& spec,
                                                          const GeneratorOptions& options = {});

// Exact number of triangles `spec` streams, without streaming it. Cheap for all
// generators except gen:city, which reads its base mesh (`of`) once.
Expected<uint64_t> generator_triangle_count(const std::string& spec);

// Names of the generators, for help texts.
std::vector<std::string> generator_names();

}  // namespace outcore
