// Procedural scene generators, addressed as `gen:NAME?key=value&...` wherever a
// file is accepted. Every generator streams (memory independent of its size)
// and is deterministic for a given spec (seeded). Unknown names and unknown or
// out-of-range parameters are errors that name the parameter.
//
// Thread-safety: the returned source is used by one thread at a time.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"

namespace outcore {

// spec starts with "gen:".
Expected<std::unique_ptr<TriangleSource>> make_generator(const std::string& spec);

// Names of the generators, for help texts.
std::vector<std::string> generator_names();

}  // namespace outcore
