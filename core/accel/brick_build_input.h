// The checks every brick structure makes on a loaded brick before building
// it, with the same wording whichever structure builds it.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

// "building brick <id> (<structure>)": the prefix of a build's errors.
std::string brick_build_context(const BrickData& brick, std::string_view structure);

// INVALID_ARGUMENT when the brick's ids and triangles differ in count,
// OUT_OF_RANGE when it has more than max_triangles; each message starts with
// `context`.
Status check_brick_build_input(const BrickData& brick, const std::string& context, uint64_t max_triangles);

// Keeps only the triangles that can be hit (finite, not degenerate) and their
// ids, in input order, compacted in place (the brick's own vectors are kept).
void keep_usable_triangles(BrickData& brick);

}  // namespace outcore
