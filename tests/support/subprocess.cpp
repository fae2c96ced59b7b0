#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

extern char** environ;

namespace outcore::testing {

namespace {

using Clock = std::chrono::steady_clock;

// Set (to the report pipe's fd) in the environment of the re-executed test
// binary; its presence turns that process into the launcher.
constexpr char kReportFdVariable[] = "OUTCORE_TEST_SUBPROCESS_REPORT_FD";
constexpr char kLauncherName[] = "outcore-test-subprocess-launcher";

// Launcher -> test process messages; each is written with one write() of less
// than PIPE_BUF bytes, so it arrives whole.
struct Report {
  enum Kind : int32_t { kStarted = 1, kForkFailed = 2, kExited = 3 };
  int32_t kind = 0;
  int32_t pid = 0;
  int32_t wait_status = 0;
  int32_t error = 0;
  int64_t max_rss_kib = 0;
};

void write_report(int fd, const Report& report) {
  while (::write(fd, &report, sizeof report) < 0 && errno == EINTR) {
  }
}

// ---- the launcher: runs before main() in the re-executed test binary --------

[[noreturn]] void launcher_main(int report_fd) {
  std::vector<std::string> args;
  {
    std::ifstream cmdline("/proc/self/cmdline", std::ios::binary);
    std::string all((std::istreambuf_iterator<char>(cmdline)), std::istreambuf_iterator<char>());
    std::size_t start = 0;
    while (start < all.size()) {
      const std::size_t end = all.find('\0', start);
      args.push_back(all.substr(start, end == std::string::npos ? std::string::npos : end - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  // args[0] is the launcher's name; the command follows.
  std::vector<char*> argv;
  for (std::size_t i = 1; i < args.size(); ++i) argv.push_back(args[i].data());
  argv.push_back(nullptr);
  if (argv.size() < 2) {
    write_report(report_fd, {Report::kForkFailed, 0, 0, EINVAL, 0});
    ::_exit(0);
  }

  const pid_t pid = ::fork();
  if (pid < 0) {
    write_report(report_fd, {Report::kForkFailed, 0, 0, errno, 0});
    ::_exit(0);
  }
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    ::execv(argv[0], argv.data());
    const int error = errno;
    const std::string message = std::string("cannot execute ") + argv[0] + ": " + std::strerror(error) + "\n";
    [[maybe_unused]] const ssize_t ignored = ::write(STDERR_FILENO, message.data(), message.size());
    ::_exit(127);
  }
  write_report(report_fd, {Report::kStarted, pid, 0, 0, 0});
  int status = 0;
  rusage usage{};
  while (::wait4(pid, &status, 0, &usage) < 0) {
    if (errno != EINTR) {
      write_report(report_fd, {Report::kExited, pid, 0, errno, 0});
      ::_exit(0);
    }
  }
  write_report(report_fd, {Report::kExited, pid, status, 0, static_cast<int64_t>(usage.ru_maxrss)});
  ::_exit(0);
}

[[maybe_unused]] const bool kLauncherChecked = [] {
  if (const char* fd_text = std::getenv(kReportFdVariable)) {
    const int fd = std::atoi(fd_text);
    ::fcntl(fd, F_SETFD, FD_CLOEXEC);
    ::unsetenv(kReportFdVariable);
    launcher_main(fd);
  }
  return true;
}();

// ---- the test-process side ----------------------------------------------------

class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() { reset(); }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }
  void reset(int fd = -1) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = fd;
  }

 private:
  int fd_ = -1;
};

// An anonymous (already unlinked) temporary file for a captured stream.
int capture_file() {
  std::string pattern = (std::filesystem::temp_directory_path() / "outcore-capture-XXXXXX").string();
  const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
  if (fd >= 0) ::unlink(pattern.c_str());
  return fd;
}

std::string read_all(int fd) {
  std::string text;
  if (::lseek(fd, 0, SEEK_SET) < 0) return text;
  char buffer[1 << 16];
  for (;;) {
    const ssize_t got = ::read(fd, buffer, sizeof buffer);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) break;
    text.append(buffer, static_cast<std::size_t>(got));
  }
  return text;
}

// Waits up to `wait` (negative: forever) for a report. 1: got one; 0: nothing
// yet; -1: the launcher closed the pipe without one.
int read_report(int fd, std::chrono::milliseconds wait, Report& report) {
  pollfd p{fd, POLLIN, 0};
  const int ready = ::poll(&p, 1, wait.count() < 0 ? -1 : static_cast<int>(wait.count()));
  if (ready == 0 || (ready < 0 && errno == EINTR)) return 0;
  if (ready < 0) return -1;
  ssize_t got;
  do {
    got = ::read(fd, &report, sizeof report);
  } while (got < 0 && errno == EINTR);
  return got == static_cast<ssize_t>(sizeof report) ? 1 : -1;
}

}  // namespace

std::string SubprocessResult::describe() const {
  std::string text;
  if (!started) {
    text = "not started: " + error;
  } else if (term_signal != 0) {
    text = "killed by signal " + std::to_string(term_signal);
  } else {
    text = "exit " + std::to_string(exit_code);
  }
  if (timed_out) text += " (timed out)";
  if (interrupted) text += " (interrupted)";
  return text + "; stderr:\n" + stderr_text;
}

SubprocessResult run_subprocess(const std::vector<std::string>& argv, const SubprocessOptions& options) {
  SubprocessResult result;
  if (argv.empty()) {
    result.error = "empty argv";
    return result;
  }
  Fd out(capture_file()), err(capture_file()), null_in(::open("/dev/null", O_RDONLY | O_CLOEXEC));
  if (out.get() < 0 || err.get() < 0 || null_in.get() < 0) {
    result.error = std::string("cannot create capture files: ") + std::strerror(errno);
    return result;
  }
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) {
    result.error = std::string("pipe2: ") + std::strerror(errno);
    return result;
  }
  Fd report_read(pipe_fds[0]), report_write(pipe_fds[1]);

  // Everything the child needs is built before fork(): between fork and exec a
  // child of a multi-threaded process may only make async-signal-safe calls.
  std::vector<std::string> launcher_args{kLauncherName};
  launcher_args.insert(launcher_args.end(), argv.begin(), argv.end());
  std::vector<char*> launcher_argv;
  for (std::string& a : launcher_args) launcher_argv.push_back(a.data());
  launcher_argv.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e != nullptr; ++e) {
    if (std::strncmp(*e, kReportFdVariable, sizeof kReportFdVariable - 1) != 0) env_strings.emplace_back(*e);
  }
  env_strings.push_back(std::string(kReportFdVariable) + "=" + std::to_string(report_write.get()));
  std::vector<char*> envp;
  for (std::string& e : env_strings) envp.push_back(e.data());
  envp.push_back(nullptr);
  const char* self = "/proc/self/exe";

  const pid_t launcher = ::fork();
  if (launcher < 0) {
    result.error = std::string("fork: ") + std::strerror(errno);
    return result;
  }
  if (launcher == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    ::dup2(null_in.get(), STDIN_FILENO);
    ::dup2(out.get(), STDOUT_FILENO);
    ::dup2(err.get(), STDERR_FILENO);
    ::fcntl(report_write.get(), F_SETFD, 0);  // the launcher keeps the report pipe
    ::execve(self, launcher_argv.data(), envp.data());
    ::_exit(126);
  }
  report_write.reset();

  Report report;
  bool exited = false;
  int status = 0;
  if (read_report(report_read.get(), std::chrono::milliseconds(-1), report) != 1 ||
      report.kind != Report::kStarted) {
    result.error = report.kind == Report::kForkFailed
                       ? std::string("the launcher cannot fork: ") + std::strerror(report.error)
                       : "the launcher died before starting the command";
  } else {
    result.started = true;
    const pid_t child = report.pid;
    const auto start = Clock::now();
    for (;;) {
      const auto now = Clock::now();
      auto wait = std::chrono::milliseconds(-1);
      auto consider = [&](Clock::time_point deadline) {
        const auto left = std::max<std::chrono::milliseconds>(
            std::chrono::milliseconds(0), std::chrono::ceil<std::chrono::milliseconds>(deadline - now));
        if (wait.count() < 0 || left < wait) wait = left;
      };
      if (options.timeout.count() > 0 && !result.timed_out) consider(start + options.timeout);
      if (!result.interrupted) {
        if (options.interrupt_after.count() >= 0) consider(start + options.interrupt_after);
        if (options.interrupt_when) consider(now + std::chrono::milliseconds(1));
      }
      const int got = read_report(report_read.get(), wait, report);
      if (got < 0) {
        result.error = "the launcher died while the command ran";
        break;
      }
      if (got == 1 && report.kind == Report::kExited) {
        result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
        exited = true;
        status = report.wait_status;
        result.peak_rss_bytes = static_cast<uint64_t>(report.max_rss_kib) * 1024;
        break;
      }
      const auto later = Clock::now();
      if (!result.interrupted &&
          ((options.interrupt_after.count() >= 0 && later >= start + options.interrupt_after) ||
           (options.interrupt_when && options.interrupt_when()))) {
        ::kill(child, SIGINT);
        result.interrupted = true;
      }
      if (options.timeout.count() > 0 && !result.timed_out && later >= start + options.timeout) {
        ::kill(child, SIGKILL);
        result.timed_out = true;
      }
    }
  }
  int launcher_status = 0;
  while (::waitpid(launcher, &launcher_status, 0) < 0 && errno == EINTR) {
  }
  if (exited) {
    if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
    if (WIFSIGNALED(status)) result.term_signal = WTERMSIG(status);
  }
  result.stdout_text = read_all(out.get());
  result.stderr_text = read_all(err.get());
  return result;
}

SubprocessResult run_outcore(std::vector<std::string> args, std::chrono::milliseconds timeout) {
  args.insert(args.begin(), outcore_binary());
  SubprocessOptions options;
  options.timeout = timeout;
  return run_subprocess(args, options);
}

}  // namespace outcore::testing
