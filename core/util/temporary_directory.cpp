#include "core/util/temporary_directory.h"

#include <fcntl.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <system_error>

namespace outcore {

namespace {

namespace fs = std::filesystem;

constexpr char kPartialInfix[] = ".partial-";
constexpr std::size_t kSuffixLength = 6;
constexpr char kSuffixAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789";

std::string random_suffix() {
  // mkdtemp's alphabet and length; random_device reads the kernel's getrandom,
  // so two processes started together do not race for the same names.
  static thread_local std::mt19937_64 engine{(static_cast<uint64_t>(std::random_device{}()) << 32) ^
                                             std::random_device{}()};
  std::uniform_int_distribution<std::size_t> pick(0, sizeof kSuffixAlphabet - 2);
  std::string suffix(kSuffixLength, 'X');
  for (char& c : suffix) c = kSuffixAlphabet[pick(engine)];
  return suffix;
}

// "PID-XXXXXX" -> PID, or 0 when `rest` is not create_beside's pattern.
long parse_partial_pid(std::string_view rest) {
  const std::size_t dash = rest.find('-');
  if (dash == 0 || dash == std::string_view::npos || dash > 10 || rest.size() != dash + 1 + kSuffixLength)
    return 0;
  long pid = 0;
  for (std::size_t i = 0; i < dash; ++i) {
    if (rest[i] < '0' || rest[i] > '9') return 0;
    pid = pid * 10 + (rest[i] - '0');
  }
  for (char c : rest.substr(dash + 1)) {
    if (std::string_view(kSuffixAlphabet).find(c) == std::string_view::npos) return 0;
  }
  return pid;
}

// Whether the directory's flock is free, i.e. no TemporaryDirectory holds it
// (in any process, whatever its pid namespace).
bool lock_is_free(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return false;
  const bool free = ::flock(fd, LOCK_EX | LOCK_NB) == 0;
  ::close(fd);
  return free;
}

}  // namespace

TemporaryDirectory::~TemporaryDirectory() {
  remove();
}

Status TemporaryDirectory::create(const std::string& prefix) {
  remove();
  std::string pattern = prefix + "XXXXXX";
  if (mkdtemp(pattern.data()) == nullptr)
    return io_error_from_errno("cannot create a temporary directory " + pattern);
  path_ = pattern;
  return Status::Ok();
}

Status TemporaryDirectory::create_beside(const std::string& output) {
  remove();
  const std::string prefix = output + kPartialInfix + std::to_string(::getpid()) + "-";
  for (int attempt = 0; attempt < 100; ++attempt) {
    const std::string path = prefix + random_suffix();
    // Not mkdtemp: its 0700 would make the store unreadable to a server
    // running as another user once this directory is renamed into place.
    if (::mkdir(path.c_str(), 0777) != 0) {
      if (errno == EEXIST) continue;
      return io_error_from_errno("cannot create a temporary directory " + path);
    }
    const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0 || ::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const Status status = io_error_from_errno("cannot lock the temporary directory " + path);
      if (fd >= 0) ::close(fd);
      ::rmdir(path.c_str());
      return status;
    }
    path_ = path;
    lock_fd_ = fd;
    return Status::Ok();
  }
  return io_error("cannot create a temporary directory " + prefix + "XXXXXX: every name tried exists");
}

void TemporaryDirectory::remove() {
  if (!path_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
    path_.clear();
  }
  // Unlocked only once removed, so nobody else ever removes it under us.
  release();
}

void TemporaryDirectory::release() {
  path_.clear();
  if (lock_fd_ >= 0) ::close(lock_fd_);
  lock_fd_ = -1;
}

std::vector<StalePartial> find_stale_partials(const std::string& output) {
  std::vector<StalePartial> stale;
  const fs::path out(output);
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  const std::string prefix = out.filename().string() + kPartialInfix;
  std::error_code ec;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!name.starts_with(prefix)) continue;
    const long pid = parse_partial_pid(std::string_view(name).substr(prefix.size()));
    if (pid <= 0) continue;
    std::error_code type_ec;
    if (!fs::is_directory(it->symlink_status(type_ec))) continue;
    // A live pid may be a reused one, and a dead-looking pid may belong to a
    // pack in another pid namespace: either way the lock must be free too.
    // Our own pid is alive by definition, so for it the lock alone decides.
    if (pid != static_cast<long>(::getpid())) {
      if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    }
    const std::string path = (parent / name).string();
    if (!lock_is_free(path)) continue;
    stale.push_back({path, pid});
  }
  return stale;
}

std::string default_temp_directory() {
  const char* dir = std::getenv("TMPDIR");
  return dir != nullptr && *dir != '\0' ? std::string(dir) : std::string("/tmp");
}

}  // namespace outcore
