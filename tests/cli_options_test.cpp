// Numeric options of every subcommand, run as the real binary: values that
// mean nothing (zero or negative counts, NaN seconds) or that overflow what
// they feed (MiB past 64-bit bytes) are errors naming the option and the
// value, before any work is done and without an output file (issue 21,
// finding 11).
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "core/ray/ray_types.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::SubprocessResult;
using testing::TempDir;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(60'000));
}

TEST(CliOptions, MeaninglessNumbersAreRejectedNamingTheOptionAndValue) {
  TempDir dir;
  const std::string store = dir.file("scene");
  const SubprocessResult packed = outcore({"pack", "gen:sphere?level=2", "-o", store, "-q", "--no-sync"});
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  const std::string rays = dir.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(rays, testing::make_test_rays({{-2, -2, -2}, {2, 2, 2}}, 100, 3)).ok());
  const std::string out = dir.file("out.npy");
  const std::vector<std::string> trace = {"trace", store, "--rays", rays, "-o", out};
  const auto with = [](std::vector<std::string> args, std::initializer_list<std::string> extra) {
    args.insert(args.end(), extra);
    return args;
  };

  struct Case {
    std::vector<std::string> args;
    std::vector<std::string> mentions;  // in stderr
  };
  const std::vector<Case> cases = {
      {with(trace, {"--repeat", "0"}), {"--repeat", "0"}},
      {with(trace, {"--repeat", "-3"}), {"--repeat", "-3"}},
      {with(trace, {"--threads", "-5"}), {"--threads", "-5"}},
      {with(trace, {"--threads", "1000000"}), {"--threads", "1000000"}},
      {with(trace, {"--cache-mb", "-1"}), {"--cache-mb", "-1"}},
      {{"query", "--server", "127.0.0.1:1", "--rays", rays, "-o", out, "--deadline-s", "nan"},
       {"--deadline-s", "nan"}},
      {{"query", "--server", "127.0.0.1:1", "--rays", rays, "-o", out, "--deadline-s", "-2"},
       {"--deadline-s", "-2"}},
      {{"query", "--server", "127.0.0.1:1", "--rays", rays, "-o", out, "--repeat", "0"}, {"--repeat", "0"}},
      {{"stress", "--quick", "--stride", "-1"}, {"--stride", "-1"}},
      {{"stress", "--quick", "--checked", "-1"}, {"--checked", "-1"}},
      {{"serve", dir.file("no_scene"), "--stream-gather-ms", "-5"}, {"--stream-gather-ms", "-5"}},
      {{"serve", dir.file("no_scene"), "--rpc-threads", "-1"}, {"--rpc-threads", "-1"}},
      {{"serve", dir.file("no_scene"), "--stream-group-rays", "-2"}, {"--stream-group-rays", "-2"}},
      {{"serve", dir.file("no_scene"), "--threads", "-5"}, {"--threads", "-5"}},
      {{"serve", dir.file("no_scene"), "--cache-mb", "-1"}, {"--cache-mb", "-1"}},
      {{"pack", "gen:sphere?level=2", "-o", dir.file("packed"), "-q", "--no-sync", "--mem-mb",
        "18446744073709551615"},
       {"--mem-mb", "18446744073709551615"}},
  };
  for (const Case& c : cases) {
    std::string command;
    for (const std::string& a : c.args) command += " " + a;
    const SubprocessResult r = outcore(c.args);
    ASSERT_TRUE(r.started) << r.error;
    EXPECT_NE(r.exit_code, 0) << command << "\n" << r.describe();
    EXPECT_EQ(r.term_signal, 0) << command << "\n" << r.describe();
    for (const std::string& m : c.mentions)
      EXPECT_TRUE(contains(r.stderr_text, m)) << command << ": no '" << m << "' in:\n" << r.stderr_text;
    EXPECT_FALSE(fs::exists(out)) << command << ": output written despite the error";
    EXPECT_FALSE(fs::exists(dir.file("packed"))) << command << ": a store packed despite the error";
  }

  // The boundaries themselves are accepted.
  const SubprocessResult ok = outcore(with(trace, {"--repeat", "1", "--threads", "1"}));
  EXPECT_TRUE(ok.succeeded()) << ok.describe();
  EXPECT_TRUE(fs::exists(out));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
