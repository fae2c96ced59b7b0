#include "tests/support/server_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <thread>

#include "tests/support/test_paths.h"

namespace outcore::testing {

namespace {

using Clock = std::chrono::steady_clock;

int anonymous_file() {
  std::string pattern = (std::filesystem::temp_directory_path() / "outcore-serve-log-XXXXXX").string();
  const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
  if (fd >= 0) ::unlink(pattern.c_str());
  return fd;
}

}  // namespace

std::unique_ptr<ServerProcess> ServerProcess::start(const std::string& scene,
                                                    const std::vector<std::string>& extra, std::string& error,
                                                    std::chrono::milliseconds timeout) {
  std::unique_ptr<ServerProcess> server(new ServerProcess());
  server->log_fd_ = anonymous_file();
  int pipe_fds[2];
  if (server->log_fd_ < 0 || ::pipe2(pipe_fds, O_CLOEXEC) != 0) {
    error = std::string("cannot create the server's log file or pipe: ") + std::strerror(errno);
    return nullptr;
  }
  server->stdout_fd_ = pipe_fds[0];
  // Everything the child needs is built before fork(): between fork and exec a
  // child of a multi-threaded process may only make async-signal-safe calls.
  std::vector<std::string> args{outcore_binary(), "serve", scene};
  if (std::find(extra.begin(), extra.end(), "--listen") == extra.end()) {
    args.insert(args.end(), {"--listen", "127.0.0.1:0"});
  }
  args.insert(args.end(), extra.begin(), extra.end());
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const int null_in = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  const pid_t pid = ::fork();
  if (pid < 0) {
    error = std::string("fork: ") + std::strerror(errno);
    ::close(pipe_fds[1]);
    if (null_in >= 0) ::close(null_in);
    return nullptr;
  }
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (null_in >= 0) ::dup2(null_in, STDIN_FILENO);
    ::dup2(pipe_fds[1], STDOUT_FILENO);
    ::dup2(server->log_fd_, STDERR_FILENO);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  server->pid_ = pid;
  ::close(pipe_fds[1]);
  if (null_in >= 0) ::close(null_in);

  std::string out;
  const auto give_up = Clock::now() + timeout;
  const std::string marker = "listening on ";
  for (;;) {
    const auto newline = out.find('\n');
    if (newline != std::string::npos) {
      const std::string line = out.substr(0, newline);
      if (line.rfind(marker, 0) == 0) {
        server->address_ = line.substr(marker.size());
        return server;
      }
      error = "unexpected first line from outcore serve: '" + line + "'; log:\n" + server->log();
      return nullptr;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(give_up - Clock::now()).count();
    if (left <= 0) {
      error = "outcore serve did not print 'listening on' in time; log:\n" + server->log();
      return nullptr;
    }
    pollfd p{server->stdout_fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, static_cast<int>(left));
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) continue;
    char buffer[256];
    const ssize_t got = ::read(server->stdout_fd_, buffer, sizeof buffer);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) {
      server->running();
      error = "outcore serve exited before listening (status " + std::to_string(server->wait_status_) +
              "); log:\n" + server->log();
      return nullptr;
    }
    out.append(buffer, static_cast<size_t>(got));
  }
}

ServerProcess::~ServerProcess() {
  if (pid_ > 0 && running()) {
    ::kill(pid_, SIGKILL);
    while (::waitpid(pid_, &wait_status_, 0) < 0 && errno == EINTR) {
    }
  }
  if (stdout_fd_ >= 0) ::close(stdout_fd_);
  if (log_fd_ >= 0) ::close(log_fd_);
}

void ServerProcess::signal(int signal_number) const {
  if (pid_ > 0 && !exited_) ::kill(pid_, signal_number);
}

bool ServerProcess::running() {
  if (exited_ || pid_ <= 0) return false;
  const pid_t got = ::waitpid(pid_, &wait_status_, WNOHANG);
  if (got == pid_) exited_ = true;
  return !exited_;
}

int ServerProcess::stop(int signal_number, std::chrono::milliseconds timeout) {
  signal(signal_number);
  const auto give_up = Clock::now() + timeout;
  while (running()) {
    if (Clock::now() >= give_up) {
      ::kill(pid_, SIGKILL);
      while (::waitpid(pid_, &wait_status_, 0) < 0 && errno == EINTR) {
      }
      exited_ = true;
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return WIFEXITED(wait_status_) ? WEXITSTATUS(wait_status_) : -1;
}

std::string ServerProcess::log() const {
  std::string text;
  char buffer[1 << 14];
  for (off_t offset = 0;;) {
    const ssize_t got = ::pread(log_fd_, buffer, sizeof buffer, offset);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) break;
    text.append(buffer, static_cast<size_t>(got));
    offset += got;
  }
  return text;
}

}  // namespace outcore::testing
