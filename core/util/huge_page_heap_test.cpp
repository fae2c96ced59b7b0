#include "core/util/huge_page_heap.h"

#include <gtest/gtest.h>

namespace outcore {
namespace OUTCORE_UNITY_ID {

constexpr const char* kMadvise = "always [madvise] never\n";

TEST(HugePageHeap, AddsTheTunableWhereTheKernelAdvisesByRequest) {
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, nullptr, false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("", kMadvise, nullptr, false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", kMadvise, "1", false),
            "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
}

TEST(HugePageHeap, LeavesTheProcessAloneOtherwise) {
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, "0", false), std::nullopt);     // opted out
  EXPECT_EQ(huge_page_tunables(nullptr, kMadvise, nullptr, true), std::nullopt);  // already re-executed
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", kMadvise, nullptr, false), std::nullopt);  // user's
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never\n", nullptr, false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]\n", nullptr, false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "", nullptr, false), std::nullopt);  // no such file
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
