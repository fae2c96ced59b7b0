#include "core/util/mapped_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <utility>

#include "core/util/file_type.h"

namespace outcore {
namespace {

// Reads `size` bytes of `fd` from offset 0 into `data`; the file may shrink
// meanwhile (someone else truncates it), which is an error, never a fault.
Status read_whole(int fd, char* data, std::size_t size, const std::string& path) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd, data + done, size - done, static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return io_error("cannot read " + path + ": " + std::strerror(errno));
    if (n == 0) {
      return io_error("cannot read " + path + ": it shrank while being read (" + std::to_string(done) +
                      " of " + std::to_string(size) + " bytes)");
    }
    done += static_cast<std::size_t>(n);
  }
  return Status::Ok();
}

// Opens `path` for reading and stats it: NOT_FOUND or IO_ERROR, also for
// anything but a regular file. O_NONBLOCK: a FIFO put under the name (a
// subtree tier directory other users may write) would otherwise hold the
// caller in open() until a writer came; reads of a regular file ignore it.
Expected<int> open_for_reading(const std::string& path, struct stat* info) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const int error = errno;
    if (error == ENOENT || error == ENOTDIR) return not_found("no file " + path);
    return io_error("cannot open " + path + ": " + std::strerror(error));
  }
  if (fstat(fd, info) != 0) {
    const int error = errno;
    ::close(fd);
    return io_error("cannot stat " + path + ": " + std::strerror(error));
  }
  if (!S_ISREG(info->st_mode)) {
    ::close(fd);
    return io_error(path + " is " + file_type_name(info->st_mode) + ", not a regular file");
  }
  return fd;
}

std::size_t round_up(std::size_t bytes, std::size_t step) {
  return (bytes + step - 1) / step * step;
}

std::size_t page_bytes() {
  static const std::size_t bytes = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  return bytes;
}

// Maps `bytes` from `data` (page aligned) in one call rather than a fault
// per page as the read writes them (about a quarter of a 2 MB read); a hint
// (Linux >= 5.14): without it the read faults them in.
void populate(char* data, std::size_t bytes) {
#ifdef MADV_POPULATE_WRITE
  if (bytes > 0) (void)madvise(data, bytes, MADV_POPULATE_WRITE);
#else
  (void)data;
  (void)bytes;
#endif
}

}  // namespace

FileIdentity identity_of(const struct stat& info) {
  return {static_cast<uint64_t>(info.st_dev), static_cast<uint64_t>(info.st_ino),
          static_cast<uint64_t>(info.st_size),
          static_cast<int64_t>(info.st_mtim.tv_sec) * 1000000000 + info.st_mtim.tv_nsec};
}

Expected<FileIdentity> file_identity(const std::string& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0) {
    const int error = errno;
    if (error == ENOENT || error == ENOTDIR) return not_found("no file " + path);
    return io_error("cannot stat " + path + ": " + std::strerror(error));
  }
  return identity_of(info);
}

MappedFile::~MappedFile() {
  if (data_ != nullptr) munmap(const_cast<char*>(data_), capacity_);
}

MappedFile::MappedFile(MappedFile&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      capacity_(std::exchange(other.capacity_, 0)),
      identity_(other.identity_),
      copy_(other.copy_) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    if (data_ != nullptr) munmap(const_cast<char*>(data_), capacity_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    capacity_ = std::exchange(other.capacity_, 0);
    identity_ = other.identity_;
    copy_ = other.copy_;
  }
  return *this;
}

void MappedFile::release_pages() const {
  // A read-only file mapping has no dirty pages: dropping them loses nothing.
  // A copy loses its bytes, which its owner reads again (read_again) first.
  // Past size_ a copy has no populated pages (read_again keeps it so).
  if (data_ != nullptr) (void)madvise(const_cast<char*>(data_), size_, MADV_DONTNEED);
}

Expected<MappedFile> MappedFile::open(const std::string& path) {
  struct stat info {};
  OUTCORE_ASSIGN_OR_RETURN(const int fd, open_for_reading(path, &info));
  MappedFile file;
  file.size_ = static_cast<std::size_t>(info.st_size);
  file.identity_ = identity_of(info);
  if (file.size_ > 0) {
    void* data = mmap(nullptr, file.size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (data == MAP_FAILED) {
      const int error = errno;
      ::close(fd);
      file.size_ = 0;
      return io_error("cannot map " + path + ": " + std::strerror(error));
    }
    file.data_ = static_cast<const char*>(data);
    file.capacity_ = file.size_;
  }
  ::close(fd);  // the mapping keeps the file
  return file;
}

Expected<MappedFile> MappedFile::copy(const std::string& path) {
  struct stat info {};
  Expected<int> fd = open_for_reading(path, &info);
  if (!fd.ok()) return fd.status();
  MappedFile file;
  file.copy_ = true;
  file.identity_ = identity_of(info);
  const auto size = static_cast<std::size_t>(info.st_size);
  if (size > 0) {
    // No MAP_POPULATE: it would populate the whole capacity, and only the
    // file's pages are to hold anything.
    const std::size_t capacity = round_up(size, kCopyCapacityStep);
    void* data = mmap(nullptr, capacity, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (data == MAP_FAILED) {
      const int error = errno;
      ::close(*fd);
      return io_error("cannot map " + std::to_string(capacity) + " bytes for " + path + ": " +
                      std::strerror(error));
    }
    file.data_ = static_cast<const char*>(data);
    file.size_ = size;
    file.capacity_ = capacity;
    populate(static_cast<char*>(data), round_up(size, page_bytes()));
    const Status read = read_whole(*fd, static_cast<char*>(data), size, path);
    if (!read.ok()) {
      ::close(*fd);
      return read;
    }
  }
  ::close(*fd);
  return file;
}

Status MappedFile::read_again(const std::string& path, bool pages_kept) {
  if (!copy_) return failed_precondition("read_again: " + path + " is mapped, not copied");
  struct stat info {};
  Expected<int> fd = open_for_reading(path, &info);
  if (!fd.ok()) return fd.status();
  const FileIdentity now = identity_of(info);
  if (now.size > capacity_) {
    ::close(*fd);
    return failed_precondition(path + " now has " + std::to_string(now.size) + " bytes, more than the " +
                               std::to_string(capacity_) + " of its copy");
  }
  char* data = const_cast<char*>(data_);
  const std::size_t populated = pages_kept ? round_up(size_, page_bytes()) : 0;
  const std::size_t wanted = round_up(static_cast<std::size_t>(now.size), page_bytes());
  if (populated > wanted) {
    // A smaller file than the one these pages held: the rest would stay in
    // the RSS, beyond what the caller accounts for this file.
    (void)madvise(data + wanted, populated - wanted, MADV_DONTNEED);
  } else {
    populate(data + populated, wanted - populated);
  }
  size_ = static_cast<std::size_t>(now.size);
  identity_ = now;
  const Status read = read_whole(*fd, data, size_, path);
  ::close(*fd);
  return read;
}

}  // namespace outcore
