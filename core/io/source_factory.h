// Kept for callers in core/accel (owned elsewhere) until they include
// core/source/source_factory.h, where open_triangle_source now lives.
#pragma once

#include "core/source/source_factory.h"
