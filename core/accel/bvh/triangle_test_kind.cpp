#include "core/accel/bvh/triangle_test_kind.h"

#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"

namespace outcore {

std::string_view triangle_test_name(TriangleTest test) {
  switch (test) {
    case TriangleTest::kMt: return MtTriangleTest::kName;
    case TriangleTest::kWatertight: return WatertightTriangleTest::kName;
    case TriangleTest::kDouble: return DoubleTriangleTest::kName;
  }
  return "?";
}

std::optional<TriangleTest> triangle_test_from_name(std::string_view name) {
  for (const TriangleTest test : kAllTriangleTests) {
    if (name == triangle_test_name(test)) return test;
  }
  return std::nullopt;
}

}  // namespace outcore
