#include "core/util/mapped_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace outcore {
namespace {

FileIdentity identity_of(const struct stat& info) {
  return {static_cast<uint64_t>(info.st_dev), static_cast<uint64_t>(info.st_ino),
          static_cast<uint64_t>(info.st_size),
          static_cast<int64_t>(info.st_mtim.tv_sec) * 1000000000 + info.st_mtim.tv_nsec};
}

}  // namespace

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
  if (data_ != nullptr) munmap(const_cast<char*>(data_), size_);
}

MappedFile::MappedFile(MappedFile&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      identity_(other.identity_) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    if (data_ != nullptr) munmap(const_cast<char*>(data_), size_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    identity_ = other.identity_;
  }
  return *this;
}

void MappedFile::will_need() const {
  if (data_ != nullptr) (void)madvise(const_cast<char*>(data_), size_, MADV_WILLNEED);  // a hint
}

void MappedFile::release_pages() const {
  // A read-only private mapping has no dirty pages: dropping them loses nothing.
  if (data_ != nullptr) (void)madvise(const_cast<char*>(data_), size_, MADV_DONTNEED);
}

Expected<MappedFile> MappedFile::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    if (error == ENOENT || error == ENOTDIR) return not_found("no file " + path);
    return io_error("cannot open " + path + ": " + std::strerror(error));
  }
  struct stat info {};
  if (fstat(fd, &info) != 0) {
    const int error = errno;
    ::close(fd);
    return io_error("cannot stat " + path + ": " + std::strerror(error));
  }
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
  }
  ::close(fd);  // the mapping keeps the file
  return file;
}

}  // namespace outcore
