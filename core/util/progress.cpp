#include "core/util/progress.h"

#include <unistd.h>

#include <cmath>

namespace outcore {

ProgressBar::ProgressBar(std::string label, uint64_t total, std::string unit, bool enabled, std::FILE* out)
    : label_(std::move(label)),
      total_(total),
      unit_(std::move(unit)),
      enabled_(enabled),
      out_(out),
      is_tty_(enabled && isatty(fileno(out)) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() {
  if (enabled_ && !finished_ && is_tty_) std::fputc('\n', out_);
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
  if (is_tty_) {
    if (!final_line && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    char bar[31];
    const int filled = static_cast<int>(fraction * 30);
    for (int i = 0; i < 30; ++i) bar[i] = i < filled ? '=' : (i == filled ? '>' : ' ');
    bar[30] = '\0';
    if (total_ > 0) {
      std::fprintf(out_, "\r%-12s [%s] %5.1f%% %s/%s %s  %s %s/s  %.1fs\x1b[K", label_.c_str(), bar,
                   fraction * 100, human_count(done).c_str(), human_count(total_).c_str(), unit_.c_str(),
                   human_count(rate).c_str(), unit_.c_str(), seconds);
    } else {
      std::fprintf(out_, "\r%-12s %s %s  %s %s/s  %.1fs\x1b[K", label_.c_str(), human_count(done).c_str(),
                   unit_.c_str(), human_count(rate).c_str(), unit_.c_str(), seconds);
    }
    if (final_line) std::fputc('\n', out_);
    std::fflush(out_);
    return;
  }
  // Not a terminal: one line per 10% step (or every 10 s when the total is unknown).
  int decile;
  if (total_ > 0) {
    decile = static_cast<int>(fraction * 10);
  } else {
    decile = static_cast<int>(seconds / 10);
  }
  // Short work stays silent in logs; a final line only closes a reported run.
  if (seconds < 1.0 && last_decile_ < 0) return;
  if (!final_line && decile <= last_decile_) return;
  last_decile_ = decile;
  if (total_ > 0) {
    std::fprintf(out_, "%s: %3.0f%% %s/%s %s, %s %s/s, %.1fs\n", label_.c_str(), fraction * 100,
                 human_count(done).c_str(), human_count(total_).c_str(), unit_.c_str(), human_count(rate).c_str(),
                 unit_.c_str(), seconds);
  } else {
    std::fprintf(out_, "%s: %s %s, %s %s/s, %.1fs\n", label_.c_str(), human_count(done).c_str(), unit_.c_str(),
                 human_count(rate).c_str(), unit_.c_str(), seconds);
  }
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
