// with_scalar_triangle_test: calls fn.template operator()<Test>() with the
// scalar triangle test a TriangleTest names, so that a brick structure's
// per-ray loop is compiled once per test (no virtual or indirect call per
// ray): the one switch per brick call. Used by the split-plane trees.
//
// Thread-safety: a pure function.
#pragma once

#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/watertight_triangle_test.h"

namespace outcore {

template <class Fn>
void with_scalar_triangle_test(TriangleTest test, Fn&& fn) {
  switch (test) {
    case TriangleTest::kMt: return fn.template operator()<MtTriangleTest>();
    case TriangleTest::kWatertight: return fn.template operator()<WatertightTriangleTest>();
    case TriangleTest::kDouble: return fn.template operator()<DoubleTriangleTest>();
  }
}

}  // namespace outcore
