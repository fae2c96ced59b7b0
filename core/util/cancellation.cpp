#include "core/util/cancellation.h"

#include <atomic>
#include <csignal>

namespace outcore {

namespace {
std::atomic<bool> g_cancel{false};
static_assert(std::atomic<bool>::is_always_lock_free);

void on_signal(int sig) {
  if (g_cancel.exchange(true)) {
    std::signal(sig, SIG_DFL);
    std::raise(sig);
  }
}
}  // namespace

void install_cancel_signal_handlers() {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
}
bool cancel_requested() {
  return g_cancel.load(std::memory_order_relaxed);
}
void request_cancel() {
  g_cancel.store(true);
}
void reset_cancel() {
  g_cancel.store(false);
}

}  // namespace outcore
