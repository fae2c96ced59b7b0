#include "core/accel/embree_device.h"

#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include <string>

#include "core/accel/accel_test_util.h"
#include "core/accel/embree_brick.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(EmbreeDevice, IsOneDevice) {
  auto a = EmbreeDevice::instance();
  auto b = EmbreeDevice::instance();
  ASSERT_TRUE(a.ok()) << a.status().to_string();
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(*a, *b);
  EXPECT_NE((*a)->handle(), nullptr);
}

TEST(EmbreeDevice, ErrorsBecomeStatus) {
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  EXPECT_TRUE((*device)->take_error("nothing").ok());
  // An invalid call: a geometry of a type Embree does not know.
  RTCGeometry geometry = rtcNewGeometry((*device)->handle(), static_cast<RTCGeometryType>(9999));
  EXPECT_EQ(geometry, nullptr);
  const Status status = (*device)->take_error("making a geometry");
  ASSERT_FALSE(status.ok());
  EXPECT_TRUE(contains(status.message(), "making a geometry: Embree RTC_ERROR_")) << status.message();
  EXPECT_TRUE((*device)->take_error("again").ok()) << "taking the error clears it";
}

// The monitor's counter moves by exactly what a brick reports, up on build and
// down on release; a section sees the build's bytes and its peak.
TEST(EmbreeDevice, MonitorAttributesBytesToOneBrick) {
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  const int64_t before = (*device)->live_bytes();
  auto accel = EmbreeBrickAccel::build(accel_test::load_brick_from("gen:sphere?level=5"), {});
  ASSERT_TRUE(accel.ok());
  EXPECT_EQ((*device)->live_bytes() - before, static_cast<int64_t>((*accel)->embree_bytes()));
  EXPECT_GT((*accel)->embree_bytes(), 20480u * 32);  // BVH nodes and leaves: tens of bytes per triangle
  accel->reset();
  EXPECT_EQ((*device)->live_bytes(), before);

  EmbreeDevice::MeasuredSection section(**device, /*allow_parallel=*/false);
  EXPECT_EQ(section.delta_bytes(), 0);
  EXPECT_EQ(section.peak_delta_bytes(), 0);
}

// Bricks built at the same time on several threads (one of them may commit in
// parallel, the others each on its own thread) are each measured exactly as
// when built alone, and no byte escapes every section.
TEST(EmbreeDevice, ConcurrentBuildsAreEachMeasuredAsWhenBuiltAlone) {
  auto device = EmbreeDevice::instance();
  ASSERT_TRUE(device.ok());
  const int64_t before = (*device)->live_bytes();
  const int64_t unattributed_before = (*device)->unattributed_bytes();
  const std::vector<std::string> specs = {"gen:sphere?level=5", "gen:torus?nu=200&nv=100",
                                          "gen:terrain?n=120&size=4"};
  std::vector<uint64_t> alone;
  for (const std::string& spec : specs) {
    auto accel = EmbreeBrickAccel::build(accel_test::load_brick_from(spec), {});
    ASSERT_TRUE(accel.ok());
    alone.push_back((*accel)->embree_bytes());
  }
  constexpr int kThreads = 6;
  std::vector<std::vector<uint64_t>> measured(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int round = 0; round < 3; ++round) {
        const std::size_t k = (t + round) % specs.size();
        auto accel = EmbreeBrickAccel::build(accel_test::load_brick_from(specs[k]), {});
        ASSERT_TRUE(accel.ok());
        EXPECT_EQ((*accel)->embree_bytes(), alone[k]) << specs[k];
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ((*device)->live_bytes(), before);
  EXPECT_EQ((*device)->unattributed_bytes(), unattributed_before);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
