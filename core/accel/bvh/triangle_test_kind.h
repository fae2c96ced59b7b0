// TriangleTest: the bvh brick's ray/triangle tests by name (the
// triangle_test option and --triangle-test): mt (mt_triangle_test.h),
// watertight (watertight_triangle_test.h), double (double_triangle_test.h).
//
// Thread-safety: plain values and pure functions.
#pragma once

#include <optional>
#include <string_view>

namespace outcore {

enum class TriangleTest { kMt, kWatertight, kDouble };
inline constexpr TriangleTest kAllTriangleTests[] = {TriangleTest::kMt, TriangleTest::kWatertight,
                                                     TriangleTest::kDouble};

std::string_view triangle_test_name(TriangleTest test);
std::optional<TriangleTest> triangle_test_from_name(std::string_view name);

}  // namespace outcore
