// ProgressBar: shows how far long work (pack, bench) has come. On a terminal it
// redraws one line in place at most 10 times a second; otherwise (logs, CI) it
// prints a plain line at each 10% step, so logs stay short. Disabled bars cost
// one branch per call.
//
// Thread-safety: advance() may be called from several threads (atomic counter;
// drawing is serialised by a try-lock so no caller waits on it).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>

namespace outcore {

class ProgressBar {
 public:
  // total == 0 means unknown: the bar shows a count and a rate only.
  ProgressBar(std::string label, uint64_t total, std::string unit, bool enabled, std::FILE* out = stderr);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void advance(uint64_t amount);
  // Final line with the total and the mean rate.
  void finish();

 private:
  void draw(bool final_line);

  std::string label_;
  uint64_t total_;
  std::string unit_;
  bool enabled_;
  std::FILE* out_;
  bool is_tty_;
  std::atomic<uint64_t> done_{0};
  std::mutex draw_mutex_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  int last_decile_ = -1;
  bool finished_ = false;
};

// "12.3 M", "456 k": short human figures for counts and bytes.
std::string human_count(double value);
std::string human_bytes(double bytes);

}  // namespace outcore
