// Figures about the running process that summaries report (peak RSS).
//
// Thread-safety: free functions, safe from any thread.
#pragma once

#include <cstdint>

namespace outcore {

// Peak resident set size of this process so far, in bytes.
uint64_t peak_rss_bytes();
// Current resident set size, in bytes (0 if /proc is unavailable).
uint64_t current_rss_bytes();

}  // namespace outcore
