// ProgressBar: shows how far long work (pack, trace, query, stress, render,
// calibrate) has come. On a terminal it redraws one line in place at most 10
// times a second; otherwise (logs, CI) it prints a plain line at each 10% step,
// so logs stay short. Disabled bars cost one branch per call. With
// ProgressStyle::show_after, work that ends sooner prints nothing at all; a
// detail callback adds live figures (bricks built) to the line.
// ProgressTicker redraws a bar from a thread of its own, for work that cannot
// report as it goes (one engine call over a whole batch).
//
// Thread-safety: advance() and tick() may be called from several threads
// (atomic counter; drawing is serialised by a try-lock so no caller waits on
// it); the detail callback is called under that lock.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace outcore {

struct ProgressStyle {
  // Nothing is drawn before this much time has passed (nor a final line for
  // work that ended sooner).
  std::chrono::milliseconds show_after{0};
  // Appended to each line ("45 bricks built"); empty: nothing.
  std::function<std::string()> detail;
};

// Interactive commands show progress only for runs longer than this.
inline constexpr std::chrono::milliseconds kShowProgressAfter{2000};

class ProgressBar {
 public:
  // total == 0 means unknown: the bar shows a count and a rate only.
  ProgressBar(std::string label, uint64_t total, std::string unit, bool enabled, std::FILE* out = stderr,
              ProgressStyle style = {});
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void advance(uint64_t amount);
  bool enabled() const { return enabled_; }
  // Redraws (time and detail move on) without advancing.
  void tick();
  // Final line with the total and the mean rate.
  void finish();

 private:
  void draw(bool final_line);
  std::string detail() const;

  std::string label_;
  uint64_t total_;
  std::string unit_;
  bool enabled_;
  std::FILE* out_;
  ProgressStyle style_;
  bool drawn_ = false;  // a line was printed
  bool is_tty_;
  std::atomic<uint64_t> done_{0};
  std::mutex draw_mutex_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  int last_decile_ = -1;
  bool finished_ = false;
};

// Ticks `bar` every 100 ms from its own thread until destroyed (no thread
// for a disabled bar).
class ProgressTicker {
 public:
  explicit ProgressTicker(ProgressBar& bar);
  ~ProgressTicker();
  ProgressTicker(const ProgressTicker&) = delete;
  ProgressTicker& operator=(const ProgressTicker&) = delete;

 private:
  ProgressBar& bar_;
  std::mutex mutex_;
  std::condition_variable stop_;
  bool stopping_ = false;
  std::thread thread_;
};

// "12.3 M", "456 k": short human figures for counts and bytes.
std::string human_count(double value);
std::string human_bytes(double bytes);

}  // namespace outcore
