// A real `outcore serve` child process for the end-to-end tests: started on a
// loopback port chosen by the kernel (--listen 127.0.0.1:0), ready once it
// printed "listening on HOST:PORT" (whose address the tests then use), stopped
// with SIGTERM (or SIGINT) and checked for its exit code. Its log (stderr) is
// kept in a file and can be read at any time.
//
// The child is killed if the thread that started it exits (PR_SET_PDEATHSIG),
// so start servers from the test's main thread (SetUp / SetUpTestSuite).
//
// Thread-safety: one ServerProcess per thread; signal() may be called from any
// thread.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace outcore::testing {

class ServerProcess {
 public:
  // Starts `outcore serve SCENE --listen 127.0.0.1:0 EXTRA...` (without the
  // --listen when EXTRA has its own) and waits up to
  // `timeout` for its "listening on" line. On failure returns null and sets
  // `error` (with the server's log).
  static std::unique_ptr<ServerProcess> start(const std::string& scene, const std::vector<std::string>& extra,
                                              std::string& error,
                                              std::chrono::milliseconds timeout = std::chrono::seconds(120));
  ~ServerProcess();  // SIGKILL if still running
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // "127.0.0.1:PORT"
  const std::string& address() const { return address_; }
  pid_t pid() const { return pid_; }
  void signal(int signal_number) const;
  // Sends `signal_number` and waits up to `timeout` for the exit; returns the
  // exit code, or -1 when the server died by a signal or did not exit in time
  // (it is then killed).
  int stop(int signal_number, std::chrono::milliseconds timeout = std::chrono::seconds(60));
  // True while the process has not exited.
  bool running();
  // Everything the server wrote on stderr so far.
  std::string log() const;

 private:
  ServerProcess() = default;
  pid_t pid_ = -1;
  bool exited_ = false;
  int wait_status_ = 0;
  int stdout_fd_ = -1;
  int log_fd_ = -1;
  std::string address_;
};

}  // namespace outcore::testing
