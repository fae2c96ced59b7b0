#include "core/util/huge_page_heap.h"

#include <gtest/gtest.h>

namespace outcore {
namespace OUTCORE_UNITY_ID {

TEST(HugePageHeap, AddsTheTunableWhenAsked) {
  EXPECT_EQ(huge_page_tunables(nullptr, "1", false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("", "1", false), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", "1", false),
            "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
}

TEST(HugePageHeap, LeavesTheProcessAloneOtherwise) {
  EXPECT_EQ(huge_page_tunables(nullptr, nullptr, false), std::nullopt);  // not asked for
  EXPECT_EQ(huge_page_tunables(nullptr, "0", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "yes", false), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "1", true), std::nullopt);                    // already re-executed
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", "1", false), std::nullopt);  // the user's
}

TEST(HugePageHeap, OnlyAKernelGivingHugePagesOnRequestQualifies) {
  EXPECT_TRUE(huge_pages_on_request("always [madvise] never\n"));
  EXPECT_FALSE(huge_pages_on_request("[always] madvise never\n"));
  EXPECT_FALSE(huge_pages_on_request("always madvise [never]\n"));
  EXPECT_FALSE(huge_pages_on_request(""));  // no such file
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
