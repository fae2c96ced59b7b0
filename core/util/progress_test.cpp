// ProgressBar as logs see it (not a terminal): silent for work shorter than
// show_after, a line per 10% step and at least every 10 s otherwise, the
// detail appended, and a ticker that redraws without advancing.
#include "core/util/progress.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <thread>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// What a bar wrote into a temporary file (never a terminal).
class CapturedOutput {
 public:
  CapturedOutput() : file_(std::tmpfile()) {}
  ~CapturedOutput() { std::fclose(file_); }
  std::FILE* file() { return file_; }
  std::string text() {
    std::fflush(file_);
    std::rewind(file_);
    std::string text;
    char buffer[4096];
    std::size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, file_)) > 0) text.append(buffer, n);
    return text;
  }

 private:
  std::FILE* file_;
};

TEST(ProgressBar, WorkShorterThanShowAfterPrintsNothing) {
  CapturedOutput out;
  {
    ProgressStyle style;
    style.show_after = std::chrono::milliseconds(60'000);
    ProgressBar bar("trace", 100, "rays", true, out.file(), std::move(style));
    ProgressTicker ticker(bar);
    bar.advance(50);
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    bar.advance(50);
    bar.finish();
  }
  EXPECT_EQ(out.text(), "");
}

TEST(ProgressBar, LongWorkPrintsStepsTheDetailAndAFinalLine) {
  CapturedOutput out;
  {
    ProgressStyle style;
    style.show_after = std::chrono::milliseconds(0);
    style.detail = [] { return std::string("7 bricks built"); };
    ProgressBar bar("trace", 1000, "rays", true, out.file(), std::move(style));
    // The non-terminal form waits a second before its first line.
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));
    bar.advance(500);
    bar.advance(500);
    bar.finish();
  }
  const std::string text = out.text();
  EXPECT_NE(text.find("trace:  50% 500/1000 rays"), std::string::npos) << text;
  EXPECT_NE(text.find("trace: 100% 1000/1000 rays"), std::string::npos) << text;
  EXPECT_NE(text.find(", 7 bricks built\n"), std::string::npos) << text;
}

TEST(ProgressBar, DisabledBarsPrintNothing) {
  CapturedOutput out;
  {
    ProgressBar bar("query", 10, "rays", false, out.file());
    ProgressTicker ticker(bar);
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    bar.advance(10);
    bar.finish();
  }
  EXPECT_EQ(out.text(), "");
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
