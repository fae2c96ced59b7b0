// Cooperative cancellation for long work (pack, bench): SIGINT/SIGTERM set a
// flag that loops poll between batches, so interrupted work unwinds through its
// normal error path and cleans up what it half-wrote.
//
// Thread-safety: the flag is an atomic; safe from any thread and from signal
// handlers.
#pragma once

namespace outcore {

// Installs SIGINT/SIGTERM handlers that request cancellation. A second signal
// while cancellation is pending restores the default action (so a stuck process
// can still be killed).
void install_cancel_signal_handlers();
bool cancel_requested();
void request_cancel();
void reset_cancel();

}  // namespace outcore
