#include "core/util/shared_memory.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csetjmp>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <random>
#include <utility>

#include "core/util/file_type.h"

namespace outcore {
namespace {

// The SIGBUS guard: a thread inside guarded_copy() points t_guard at its jump
// buffer; the handler jumps back there. Faults anywhere else go to whatever
// handler was installed before ours (the sanitizers', or the default action).
thread_local sigjmp_buf* t_guard = nullptr;
struct sigaction g_previous_sigbus;
std::once_flag g_sigbus_installed;

void on_sigbus(int signal_number, siginfo_t* info, void* context) {
  if (t_guard != nullptr) siglongjmp(*t_guard, 1);
  if ((g_previous_sigbus.sa_flags & SA_SIGINFO) != 0 && g_previous_sigbus.sa_sigaction != nullptr) {
    g_previous_sigbus.sa_sigaction(signal_number, info, context);
    return;
  }
  if ((g_previous_sigbus.sa_flags & SA_SIGINFO) == 0 && g_previous_sigbus.sa_handler != SIG_DFL &&
      g_previous_sigbus.sa_handler != SIG_IGN) {
    g_previous_sigbus.sa_handler(signal_number);
    return;
  }
  // Not ours and nobody else's: the default action. Returning re-executes the
  // faulting access, which now ends the process as it would have without us.
  std::signal(SIGBUS, SIG_DFL);
}

void install_sigbus_guard() {
  struct sigaction action {};
  action.sa_sigaction = on_sigbus;
  action.sa_flags = SA_SIGINFO | SA_NODEFER;
  sigemptyset(&action.sa_mask);
  sigaction(SIGBUS, &action, &g_previous_sigbus);
}

// memcpy that reports a SIGBUS (the mapped object shrank) instead of dying.
bool guarded_copy(void* destination, const void* source, std::size_t bytes) {
  std::call_once(g_sigbus_installed, install_sigbus_guard);
  sigjmp_buf jump;
  if (sigsetjmp(jump, 1) != 0) {
    t_guard = nullptr;
    return false;
  }
  t_guard = &jump;
  std::atomic_signal_fence(std::memory_order_seq_cst);
  std::memcpy(destination, source, bytes);
  std::atomic_signal_fence(std::memory_order_seq_cst);
  t_guard = nullptr;
  return true;
}

bool name_char_ok(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
         c == '-';
}

Status range_error(const std::string& name, std::size_t offset, std::size_t bytes, std::size_t size) {
  return out_of_range(std::to_string(bytes) + " bytes at offset " + std::to_string(offset) +
                      " are not inside the mapped " + std::to_string(size) +
                      " bytes of the shared-memory object " + name);
}

Status truncated(const std::string& name) {
  return failed_precondition("the shared-memory object " + name +
                             " was truncated during the copy (SIGBUS); leave it alone while a call runs");
}

}  // namespace

SharedMemoryObject::~SharedMemoryObject() {
  release();
}

SharedMemoryObject::SharedMemoryObject(SharedMemoryObject&& other) noexcept
    : name_(std::move(other.name_)),
      token_(std::move(other.token_)),
      identity_(other.identity_),
      descriptor_(std::exchange(other.descriptor_, -1)),
      data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      mapped_(std::exchange(other.mapped_, 0)),
      owner_(std::exchange(other.owner_, false)) {}

SharedMemoryObject& SharedMemoryObject::operator=(SharedMemoryObject&& other) noexcept {
  if (this != &other) {
    release();
    name_ = std::move(other.name_);
    token_ = std::move(other.token_);
    identity_ = other.identity_;
    descriptor_ = std::exchange(other.descriptor_, -1);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    mapped_ = std::exchange(other.mapped_, 0);
    owner_ = std::exchange(other.owner_, false);
  }
  return *this;
}

void SharedMemoryObject::release() {
  if (data_ != nullptr) munmap(data_, mapped_);
  if (descriptor_ >= 0) ::close(descriptor_);
  descriptor_ = -1;
  if (owner_) shm_unlink(name_.c_str());
  data_ = nullptr;
  size_ = 0;
  mapped_ = 0;
  owner_ = false;
}

Status SharedMemoryObject::check_name(std::string_view name) {
  const std::size_t suffix = name.size() - std::min(name.size(), kNamePrefix.size());
  if (!name.starts_with(kNamePrefix) || suffix == 0 || suffix > kMaxNameSuffix) {
    return invalid_argument("shared-memory object name '" + std::string(name.substr(0, 64)) + "' is not '" +
                            std::string(kNamePrefix) + "' followed by 1 to " +
                            std::to_string(kMaxNameSuffix) + " of [A-Za-z0-9_.-]");
  }
  for (std::size_t i = kNamePrefix.size(); i < name.size(); ++i) {
    if (!name_char_ok(name[i])) {
      return invalid_argument("shared-memory object name '" + std::string(name.substr(0, 64)) +
                              "' has a character outside [A-Za-z0-9_.-] at position " + std::to_string(i));
    }
  }
  return Status::Ok();
}

namespace {

// shm_open(name) and fstat; the descriptor and what fstat said, or the
// errors open() reports. Anyone who can write /dev/shm can put a FIFO, a
// symbolic link or someone else's file under a name we accept: the object is
// opened without following links and without waiting (a FIFO opened for
// reading would block until a writer came, holding the caller's thread for
// ever), and anything but a regular file of this process's user is refused
// before it is used.
Expected<std::pair<int, struct stat>> open_and_stat(const std::string& name, int flags) {
  const int fd = shm_open(name.c_str(), flags | O_NONBLOCK | O_NOFOLLOW | O_CLOEXEC, 0);
  if (fd < 0) {
    const int error = errno;
    if (error == ENOENT) return not_found("no shared-memory object " + name);
    if (error == ELOOP) {
      return invalid_argument("the shared-memory object " + name +
                              " is a symbolic link; only regular objects are opened");
    }
    if (error == EACCES || error == EPERM) {
      return permission_denied("cannot open the shared-memory object " + name + ": " + std::strerror(error));
    }
    return io_error("cannot open the shared-memory object " + name + ": " + std::strerror(error));
  }
  struct stat info {};
  if (fstat(fd, &info) != 0) {
    const int error = errno;
    ::close(fd);
    return io_error("cannot stat the shared-memory object " + name + ": " + std::strerror(error));
  }
  if (!S_ISREG(info.st_mode)) {
    ::close(fd);
    return invalid_argument("the shared-memory object " + name + " is " + file_type_name(info.st_mode) +
                            ", not a regular file");
  }
  if (info.st_uid != geteuid()) {
    ::close(fd);
    return permission_denied("the shared-memory object " + name + " belongs to uid " +
                             std::to_string(info.st_uid) + ", not to this process's uid " +
                             std::to_string(geteuid()));
  }
  return std::pair{fd, info};
}

SharedObjectIdentity shared_object_identity_of(const struct stat& info) {
  return {static_cast<uint64_t>(info.st_dev), static_cast<uint64_t>(info.st_ino),
          static_cast<uint64_t>(info.st_size)};
}

}  // namespace

Expected<SharedObjectIdentity> SharedMemoryObject::identify(const std::string& name) {
  OUTCORE_RETURN_IF_ERROR(check_name(name));
  OUTCORE_ASSIGN_OR_RETURN(const auto opened, open_and_stat(name, O_RDONLY));
  ::close(opened.first);
  return shared_object_identity_of(opened.second);
}

bool SharedMemoryObject::unlinked() const {
  struct stat info {};
  return descriptor_ >= 0 && fstat(descriptor_, &info) == 0 && info.st_nlink == 0;
}

Expected<SharedMemoryObject> SharedMemoryObject::open(const std::string& name, std::size_t map_bytes) {
  OUTCORE_RETURN_IF_ERROR(check_name(name));
  OUTCORE_ASSIGN_OR_RETURN(const auto opened, open_and_stat(name, O_RDWR));
  const auto& [fd, info] = opened;
  const std::size_t size = static_cast<std::size_t>(info.st_size);
  const std::size_t mapped_bytes = std::min(size, map_bytes);
  char* data = nullptr;
  if (mapped_bytes > 0) {
    // MAP_POPULATE: one pass maps every page, instead of a fault per page
    // while the rays are read and the answers written.
    void* mapped = mmap(nullptr, mapped_bytes, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_POPULATE, fd, 0);
    if (mapped == MAP_FAILED) {
      const int error = errno;
      ::close(fd);
      return io_error("cannot map the shared-memory object " + name + ": " + std::strerror(error));
    }
    data = static_cast<char*>(mapped);
  }
  SharedMemoryObject object(name, data, size, mapped_bytes, /*owner=*/false);
  object.identity_ = shared_object_identity_of(info);
  object.descriptor_ = fd;  // for unlinked(); the mapping alone keeps the object
  return object;
}

Expected<SharedMemoryObject> SharedMemoryObject::create(std::string_view suffix, std::size_t bytes) {
  bytes = std::max(bytes, kHeaderBytes);
  std::random_device random;
  const uint64_t tail = (uint64_t{random()} << 32) ^ random();
  char tail_hex[17];
  std::snprintf(tail_hex, sizeof tail_hex, "%016llx", static_cast<unsigned long long>(tail));
  const std::string name = std::string(kNamePrefix) + std::string(suffix) + "-" + tail_hex;
  OUTCORE_RETURN_IF_ERROR(check_name(name));
  const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  if (fd < 0) {
    return io_error("cannot create the shared-memory object " + name + ": " + std::strerror(errno));
  }
  auto fail = [&](Status status) {
    ::close(fd);
    shm_unlink(name.c_str());
    return status;
  };
  {
    // Reserve the pages now: tmpfs would otherwise hand them out at first
    // touch and raise SIGBUS there when /dev/shm is full.
    const int error = posix_fallocate(fd, 0, static_cast<off_t>(bytes));
    if (error != 0) {
      const std::string what = "cannot reserve " + std::to_string(bytes) +
                               " bytes for the shared-memory object " + name + ": " + std::strerror(error);
      return fail(error == ENOSPC ? resource_exhausted(what) : io_error(what));
    }
  }
  void* mapped = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (mapped == MAP_FAILED) {
    return fail(io_error("cannot map the shared-memory object " + name + ": " + std::strerror(errno)));
  }
  struct stat info {};
  const bool stated = fstat(fd, &info) == 0;
  ::close(fd);
  SharedMemoryObject object(name, static_cast<char*>(mapped), bytes, bytes, /*owner=*/true);
  if (stated) object.identity_ = shared_object_identity_of(info);
  object.token_.resize(kTokenBytes);
  for (std::size_t i = 0; i < kTokenBytes; i += 4) {
    const uint32_t word = random();
    std::memcpy(object.token_.data() + i, &word, 4);
  }
  std::memcpy(object.data_, object.token_.data(), kTokenBytes);
  return object;
}

int SharedMemoryObject::remove_orphans(std::string_view client) {
  const std::string prefix = std::string(kNamePrefix.substr(1)) + std::string(client) + "-";
  DIR* directory = opendir("/dev/shm");
  if (directory == nullptr) return 0;
  int removed = 0;
  while (const dirent* entry = readdir(directory)) {
    const std::string_view file = entry->d_name;
    if (!file.starts_with(prefix)) continue;
    const std::string_view rest = file.substr(prefix.size());
    const std::size_t dash = rest.find('-');
    if (dash == 0 || dash == std::string_view::npos || dash > 9) continue;
    pid_t pid = 0;
    bool digits = true;
    for (const char c : rest.substr(0, dash)) {
      if (c < '0' || c > '9') digits = false;
      pid = pid * 10 + (c - '0');
    }
    if (!digits || pid <= 0) continue;
    // Alive (or not ours to signal): leave it. A pid taken again by another
    // process keeps its objects until that process ends too.
    if (kill(pid, 0) == 0 || errno != ESRCH) continue;
    struct stat info {};
    const std::string path = "/dev/shm/" + std::string(file);
    if (lstat(path.c_str(), &info) != 0 || !S_ISREG(info.st_mode) || info.st_uid != geteuid()) continue;
    if (shm_unlink(("/" + std::string(file)).c_str()) == 0) ++removed;
  }
  closedir(directory);
  return removed;
}

Status SharedMemoryObject::check_token(std::string_view token) const {
  if (token.size() != kTokenBytes) {
    return permission_denied("the token for the shared-memory object " + name_ + " has " +
                             std::to_string(token.size()) + " bytes, not " + std::to_string(kTokenBytes));
  }
  char header[kTokenBytes];
  OUTCORE_RETURN_IF_ERROR(copy_out(0, header, kTokenBytes));
  // Every byte compared, so the time taken says nothing about the token.
  unsigned char differ = 0;
  for (std::size_t i = 0; i < kTokenBytes; ++i) differ |= static_cast<unsigned char>(header[i] ^ token[i]);
  if (differ != 0) {
    return permission_denied("the token does not match the header of the shared-memory object " + name_ +
                             " (only its creator may name it)");
  }
  return Status::Ok();
}

Status SharedMemoryObject::copy_out(std::size_t offset, void* out, std::size_t out_bytes) const {
  if (offset > mapped_ || out_bytes > mapped_ - offset) return range_error(name_, offset, out_bytes, mapped_);
  if (out_bytes == 0) return Status::Ok();
  if (!guarded_copy(out, data_ + offset, out_bytes)) return truncated(name_);
  return Status::Ok();
}

Status SharedMemoryObject::copy_in(std::size_t offset, const void* in, std::size_t in_bytes) {
  if (offset > mapped_ || in_bytes > mapped_ - offset) return range_error(name_, offset, in_bytes, mapped_);
  if (in_bytes == 0) return Status::Ok();
  if (!guarded_copy(data_ + offset, in, in_bytes)) return truncated(name_);
  return Status::Ok();
}

}  // namespace outcore
