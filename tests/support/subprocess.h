// Runs a command in a child process for the end-to-end tests (the real
// `outcore` binary): fork/execv, stdout and stderr captured in full, exit
// status and the child's peak RSS from wait4 (rusage.ru_maxrss), an optional
// timeout (SIGKILL), and SIGINT sent after a delay or as soon as a condition
// holds (interruption tests).
//
// Peak RSS is measured cleanly: Linux counts in a child's ru_maxrss the pages
// it inherited from its parent by fork() before execv (a test process that has
// held a few hundred MiB would inflate every measurement). So the command is
// not forked from the test process itself: the test binary re-executes itself
// (/proc/self/exe) as a small launcher that, before main() and before any test
// state exists, forks and execs the command, wait4s for it and reports its pid,
// status and rusage over a pipe. The launcher's own image is a few MiB, which is
// the largest amount that can leak into the figure.
//
// Thread-safety: run_subprocess may be called from several threads at once (all
// state is local; file descriptors are close-on-exec), but `interrupt_when` runs
// on the calling thread and must be safe to call there.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace outcore::testing {

struct SubprocessOptions {
  // Kill the command (SIGKILL) after this long; zero means no limit.
  std::chrono::milliseconds timeout{0};
  // Send SIGINT this long after the command started; negative means never.
  std::chrono::milliseconds interrupt_after{-1};
  // Polled every millisecond or so while the command runs; SIGINT is sent the
  // first time it returns true.
  std::function<bool()> interrupt_when;
};

struct SubprocessResult {
  // False when the command could not be started at all (see `error`).
  bool started = false;
  std::string error;
  // Exit status when the command exited normally, else -1.
  int exit_code = -1;
  // The signal that ended the command, else 0.
  int term_signal = 0;
  bool timed_out = false;    // killed because of SubprocessOptions::timeout
  bool interrupted = false;  // SIGINT was sent
  std::string stdout_text;
  std::string stderr_text;
  // The command's peak resident set size (ru_maxrss), in bytes.
  uint64_t peak_rss_bytes = 0;
  double seconds = 0.0;  // wall time from exec to exit

  bool succeeded() const { return started && exit_code == 0; }
  // "exit 1" / "signal 9" / "not started: ..." plus stderr, for failure messages.
  std::string describe() const;
};

// argv[0] is the path of the program (execv: no PATH search).
SubprocessResult run_subprocess(const std::vector<std::string>& argv, const SubprocessOptions& options = {});

// Runs the built `outcore` binary with args, killed after timeout.
SubprocessResult run_outcore(std::vector<std::string> args, std::chrono::milliseconds timeout);

}  // namespace outcore::testing
