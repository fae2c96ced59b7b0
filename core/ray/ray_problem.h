// Which rays the engine traces: a ray with NaN or infinite components,
// components beyond kLargestRayComponent, a zero direction, a negative or
// non-finite tnear, a NaN tfar or tnear > tfar is invalid (answered as a miss,
// or an error under --strict).
//
// Thread-safety: a pure function.
#pragma once

#include "core/ray/ray_types.h"

namespace outcore {

// Why a ray is invalid, or nullptr when it is fine.
const char* ray_problem(const Ray& ray);

}  // namespace outcore
