#include "core/util/huge_page_heap.h"

#include <gtest/gtest.h>

namespace outcore {
namespace OUTCORE_UNITY_ID {

constexpr const char* kMadvise = "always [madvise] never\n";

TEST(HugePageHeap, AddsTheTunableWhenAskedWhereTheKernelAdvisesByRequest) {
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, "1", false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("", kMadvise, "1", false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", kMadvise, "1", false),
            "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
}

TEST(HugePageHeap, LeavesTheProcessAloneOtherwise) {
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, nullptr, false), std::nullopt);  // not asked for
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, "0", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, "yes", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, "1", true), std::nullopt);  // already re-executed
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", kMadvise, "1", false), std::nullopt);  // user's
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never\n", "1", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]\n", "1", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "", "1", false), std::nullopt);  // no such file
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
