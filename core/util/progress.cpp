#include "core/util/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace outcore {

ProgressBar::ProgressBar(std::string label, uint64_t total, std::string unit, bool enabled, std::FILE* out,
                         ProgressStyle style)
    : label_(std::move(label)),
      total_(total),
      unit_(std::move(unit)),
      enabled_(enabled),
      out_(out),
      style_(std::move(style)),
      is_tty_(enabled && isatty(fileno(out)) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() {
  if (enabled_ && !finished_ && is_tty_ && drawn_) std::fputc('\n', out_);
}

void ProgressBar::tick() {
  if (!enabled_) return;
  std::unique_lock lock(draw_mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  draw(false);
}

std::string ProgressBar::detail() const {
  if (!style_.detail) return "";
  return ", " + style_.detail();
}

ProgressTicker::ProgressTicker(ProgressBar& bar) : bar_(bar) {
  if (!bar.enabled()) return;  // nothing to redraw: no thread
  thread_ = std::thread([this] {
    std::unique_lock lock(mutex_);
    while (!stop_.wait_for(lock, std::chrono::milliseconds(100), [this] { return stopping_; })) {
      lock.unlock();
      bar_.tick();
      lock.lock();
    }
  });
}

ProgressTicker::~ProgressTicker() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  stop_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void ProgressBar::advance(uint64_t amount) {
  done_.fetch_add(amount, std::memory_order_relaxed);
  if (!enabled_) return;
  std::unique_lock lock(draw_mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  draw(false);
}

void ProgressBar::finish() {
  if (!enabled_ || finished_) return;
  std::lock_guard lock(draw_mutex_);
  draw(true);
  finished_ = true;
}

void ProgressBar::draw(bool final_line) {
  const auto now = std::chrono::steady_clock::now();
  const uint64_t done = done_.load(std::memory_order_relaxed);
  const double seconds = std::chrono::duration<double>(now - start_).count();
  const double rate = seconds > 0 ? done / seconds : 0.0;
  const double fraction = total_ > 0 ? std::min(1.0, static_cast<double>(done) / total_) : 0.0;
  // Work shorter than show_after stays silent, its final line included.
  if (now - start_ < style_.show_after && !drawn_) return;
  if (is_tty_) {
    if (!final_line && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    // The detail (a lock taken by the caller's figures) only for a line drawn.
    const std::string extra = detail();
    char bar[31];
    const int filled = static_cast<int>(fraction * 30);
    for (int i = 0; i < 30; ++i) bar[i] = i < filled ? '=' : (i == filled ? '>' : ' ');
    bar[30] = '\0';
    if (total_ > 0) {
      std::fprintf(out_, "\r%-12s [%s] %5.1f%% %s/%s %s  %s %s/s  %.1fs%s\x1b[K", label_.c_str(), bar,
                   fraction * 100, human_count(done).c_str(), human_count(total_).c_str(), unit_.c_str(),
                   human_count(rate).c_str(), unit_.c_str(), seconds, extra.c_str());
    } else {
      std::fprintf(out_, "\r%-12s %s %s  %s %s/s  %.1fs%s\x1b[K", label_.c_str(), human_count(done).c_str(),
                   unit_.c_str(), human_count(rate).c_str(), unit_.c_str(), seconds, extra.c_str());
    }
    drawn_ = true;
    if (final_line) std::fputc('\n', out_);
    std::fflush(out_);
    return;
  }
  // Not a terminal: one line per 10% step, and one at least every 10 s (work
  // that advances in large steps, or whose total is unknown).
  int decile;
  if (total_ > 0) {
    decile = static_cast<int>(fraction * 10);
  } else {
    decile = static_cast<int>(seconds / 10);
  }
  // Short work stays silent in logs; a final line only closes a reported run.
  if (seconds < 1.0 && last_decile_ < 0) return;
  const bool quiet_for_long = now - last_draw_ >= std::chrono::seconds(10);
  if (!final_line && decile <= last_decile_ && !quiet_for_long) return;
  last_decile_ = std::max(decile, last_decile_);
  last_draw_ = now;
  const std::string extra = detail();
  if (total_ > 0) {
    std::fprintf(out_, "%s: %3.0f%% %s/%s %s, %s %s/s, %.1fs%s\n", label_.c_str(), fraction * 100,
                 human_count(done).c_str(), human_count(total_).c_str(), unit_.c_str(),
                 human_count(rate).c_str(), unit_.c_str(), seconds, extra.c_str());
  } else {
    std::fprintf(out_, "%s: %s %s, %s %s/s, %.1fs%s\n", label_.c_str(), human_count(done).c_str(),
                 unit_.c_str(), human_count(rate).c_str(), unit_.c_str(), seconds, extra.c_str());
  }
  drawn_ = true;
  std::fflush(out_);
}

std::string human_count(double value) {
  char buf[32];
  const double a = std::fabs(value);
  if (a >= 1e9) {
    std::snprintf(buf, sizeof buf, "%.2f G", value / 1e9);
  } else if (a >= 1e6) {
    std::snprintf(buf, sizeof buf, "%.2f M", value / 1e6);
  } else if (a >= 1e4) {
    std::snprintf(buf, sizeof buf, "%.1f k", value / 1e3);
  } else {
    std::snprintf(buf, sizeof buf, "%.0f", value);
  }
  return buf;
}

std::string human_bytes(double bytes) {
  char buf[32];
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (bytes >= 1024.0 && u < 4) {
    bytes /= 1024.0;
    ++u;
  }
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.2f %s", bytes, units[u]);
  return buf;
}

}  // namespace outcore
