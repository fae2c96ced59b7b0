// Builds the UpperHierarchy over brick bounds with a full-sweep SAH (bricks
// number in the thousands, so the exact sweep is cheap and gives the best tree).
// Every leaf holds exactly one brick, so the split costs need no leaf term.
//
// Thread-safety: pure function of its input.
#pragma once

#include <span>

#include "core/geometry/aabb.h"
#include "core/upper/upper_hierarchy.h"

namespace outcore {

// brick_bounds[i] are the bounds of brick i; every brick becomes one leaf.
// Empty input gives an empty hierarchy.
UpperHierarchy build_upper_hierarchy(std::span<const Aabb> brick_bounds);

}  // namespace outcore
