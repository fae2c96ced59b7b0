#include "core/util/reuse_pool.h"

#include <gtest/gtest.h>

#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

bool small_enough(const std::vector<int>& v) {
  return v.capacity() <= 100;
}

TEST(ReusePool, AReturnedObjectIsHandedOutAgainWithItsContents) {
  ReusePool<std::vector<int>> pool(2);
  std::vector<int>* first = nullptr;
  {
    auto lease = pool.take();
    lease->assign(10, 7);
    first = lease.get();
  }
  EXPECT_EQ(pool.spares(), 1u);
  auto again = pool.take();
  EXPECT_EQ(again.get(), first);
  EXPECT_EQ(again->size(), 10u);
  EXPECT_EQ(pool.spares(), 0u);
}

TEST(ReusePool, KeepsAtMostItsCapacity) {
  ReusePool<std::vector<int>> pool(2);
  {
    auto a = pool.take();
    auto b = pool.take();
    auto c = pool.take();
  }
  EXPECT_EQ(pool.spares(), 2u);
}

TEST(ReusePool, DropsObjectsTheKeepPredicateRefuses) {
  ReusePool<std::vector<int>> pool(2, small_enough);
  {
    auto big = pool.take();
    big->resize(1000);
    auto small = pool.take();
    small->resize(10);
  }
  EXPECT_EQ(pool.spares(), 1u);
  EXPECT_LE(pool.take()->capacity(), 100u);
}

TEST(ReusePool, AMovedLeaseReturnsItsObjectOnce) {
  ReusePool<std::vector<int>> pool(4);
  {
    auto a = pool.take();
    auto b = std::move(a);
    auto c = pool.take();
    c = std::move(b);  // c's own object goes back, then b's when c ends
    EXPECT_EQ(pool.spares(), 1u);
  }
  EXPECT_EQ(pool.spares(), 2u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
