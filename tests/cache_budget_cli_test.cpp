// A cache budget smaller than the largest brick's build reservation is found
// when the scene is opened: `trace` and `serve` fail at once with an error
// naming the brick and the smallest workable --cache-mb (instead of a server
// that starts and fails every query), that figure works, and `outcore info`
// prints it.
#include <gtest/gtest.h>

#include <chrono>
#include <regex>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "tests/support/json_fields.h"
#include "tests/support/server_process.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::SubprocessResult;
using testing::TempDir;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(120'000));
}

// The N of "the smallest workable budget is N MiB" (0 when absent).
uint64_t smallest_workable_mib(const std::string& text) {
  std::smatch match;
  static const std::regex pattern("smallest workable budget is ([0-9]+) MiB");
  return std::regex_search(text, match, pattern) ? std::stoull(match[1]) : 0;
}

class CacheBudgetCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    // One brick of 81,920 triangles: several MiB to build with either structure.
    const auto packed = outcore({"pack", "gen:sphere?level=6", "-o", dir_->file("scene"), "-q"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    std::vector<Ray> rays;
    for (int i = 0; i < 64; ++i) {
      const float x = -0.5f + static_cast<float>(i) / 64.0f;
      rays.push_back(Ray{Vec3f(x, 0.1f, -5.0f), Vec3f(0.0f, 0.0f, 1.0f)});
    }
    ASSERT_TRUE(write_rays_npy(dir_->file("rays.npy"), rays).ok());
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string scene() { return dir_->file("scene"); }
  static TempDir* dir_;
};
TempDir* CacheBudgetCli::dir_ = nullptr;

TEST_F(CacheBudgetCli, TraceRefusesABudgetBelowTheLargestBrickAndNamesTheSmallestWorkable) {
  for (const char* accel : {"embree", "bvh"}) {
    SCOPED_TRACE(accel);
    auto r = outcore({"trace", scene(), "--rays", dir_->file("rays.npy"), "-o", dir_->file("hits.npy"),
                      "--cache-mb", "1", "--brick-accel", accel});
    EXPECT_EQ(r.exit_code, 1) << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, "brick 0 (81920 triangles)")) << r.stderr_text;
    EXPECT_TRUE(contains(r.stderr_text, std::string("'") + accel + "'")) << r.stderr_text;
    const uint64_t minimum = smallest_workable_mib(r.stderr_text);
    ASSERT_GT(minimum, 1u) << r.stderr_text;
    // The figure named works, and one MiB less does not.
    r = outcore({"trace", scene(), "--rays", dir_->file("rays.npy"), "-o", dir_->file("hits.npy"),
                 "--cache-mb", std::to_string(minimum), "--brick-accel", accel});
    EXPECT_TRUE(r.succeeded()) << r.describe();
    r = outcore({"trace", scene(), "--rays", dir_->file("rays.npy"), "-o", dir_->file("hits.npy"),
                 "--cache-mb", std::to_string(minimum - 1), "--brick-accel", accel});
    EXPECT_EQ(r.exit_code, 1) << r.describe();
    // `outcore info` prints the same figure, as text and as JSON.
    const auto info = outcore({"info", scene()});
    ASSERT_TRUE(info.succeeded()) << info.describe();
    EXPECT_TRUE(contains(info.stdout_text, std::to_string(minimum) + " MiB (" + accel + ")"))
        << info.stdout_text;
    const auto json = outcore({"info", scene(), "--json"});
    ASSERT_TRUE(json.succeeded()) << json.describe();
    EXPECT_EQ(testing::json_uint(json.stdout_text, accel), minimum) << json.stdout_text;
  }
}

TEST_F(CacheBudgetCli, ServeRefusesToStartUnderABudgetBelowTheLargestBrick) {
  std::string error;
  const auto start = std::chrono::steady_clock::now();
  auto server = testing::ServerProcess::start(scene(), {"--cache-mb", "1"}, error, std::chrono::seconds(60));
  EXPECT_EQ(server, nullptr) << "the server started under a budget no brick fits";
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(30));
  EXPECT_TRUE(contains(error, "smallest workable budget is")) << error;
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
