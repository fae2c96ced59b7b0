#include "core/util/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <filesystem>
#include <system_error>

#include "core/util/buffered_file.h"

namespace outcore {
namespace {

namespace fs = std::filesystem;

// Writes to an existing non-regular file (a device, a FIFO) in place.
Status write_in_place(const std::string& path, std::span<const std::string_view> parts) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return io_error_from_errno("cannot open " + path);
  for (const std::string_view part : parts) {
    if (Status written = write_fully(fd, part.data(), part.size(), path); !written.ok()) {
      ::close(fd);
      return written;
    }
  }
  if (::close(fd) != 0) return io_error_from_errno("cannot write " + path);
  return Status::Ok();
}

// Unique among threads (counter) and processes (pid); hidden (leading dot),
// so directory scans that look for the target's kind of name skip it.
std::string temporary_name_beside(const fs::path& target) {
  static std::atomic<uint64_t> sequence{0};
  const fs::path directory = target.has_parent_path() ? target.parent_path() : fs::path(".");
  return (directory / ("." + target.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                       std::to_string(sequence.fetch_add(1))))
      .string();
}

}  // namespace

AtomicFile::~AtomicFile() {
  discard();
}

void AtomicFile::prepare(const std::string& target) {
  discard();
  target_ = target;
  name_ = target;
  temp_ = temporary_name_beside(target);
}

Status AtomicFile::create(const std::string& target, const AtomicWriteOptions& options) {
  return create_named(target, options, target);
}

Status AtomicFile::create_named(const std::string& target, const AtomicWriteOptions& options,
                                const std::string& name) {
  options_ = options;
  const mode_t mode = options.mode >= 0 ? static_cast<mode_t>(options.mode) : 0666;
  for (int attempt = 0; attempt < 100 && fd_ < 0; ++attempt) {
    prepare(target);
    fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
    if (fd_ < 0 && errno != EEXIST) break;
  }
  if (fd_ < 0) {
    const Status failed = io_error_from_errno("cannot create a temporary file beside " + name);
    temp_.clear();  // not ours: nothing to remove
    return failed;
  }
  name_ = name;
  return Status::Ok();
}

Status AtomicFile::write(std::string_view bytes) {
  if (fd_ < 0) return failed_precondition("no temporary file is open for " + name_);
  const Status written = write_fully(fd_, bytes.data(), bytes.size(), name_);
  if (!written.ok()) discard();
  return written;
}

Status AtomicFile::commit() {
  const auto fail = [&](const std::string& what) {
    const Status failed = io_error_from_errno(what);
    discard();
    return failed;
  };
  if (fd_ >= 0) {
    // The umask may have cleared bits an explicit mode asks for.
    if (options_.mode >= 0 && ::fchmod(fd_, static_cast<mode_t>(options_.mode)) != 0)
      return fail("cannot set the mode of " + temp_);
    if (options_.sync && ::fsync(fd_) != 0) return fail("cannot sync " + name_);
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) return fail("cannot write " + name_);
  }
  if (::rename(temp_.c_str(), target_.c_str()) != 0) return fail("cannot rename " + temp_ + " to " + target_);
  temp_.clear();
  return Status::Ok();
}

void AtomicFile::discard() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!temp_.empty()) ::unlink(temp_.c_str());
  temp_.clear();
}

Status write_file_atomically(const std::string& path, std::span<const std::string_view> parts,
                             const AtomicWriteOptions& options) {
  if (path.empty()) return invalid_argument("no output file named");
  fs::path target(path);
  std::error_code error;
  const fs::file_status status = fs::status(target, error);  // follows links
  if (!error && fs::exists(status) && !fs::is_regular_file(status)) {
    if (fs::is_directory(status)) return io_error("cannot write " + path + ": it is a directory");
    return write_in_place(path, parts);
  }
  if (fs::is_symlink(fs::symlink_status(target, error))) {
    const fs::path resolved = fs::weakly_canonical(target, error);
    if (!error) target = resolved;
  }
  AtomicFile file;
  // Messages name the path as the caller did, not as the link resolved.
  OUTCORE_RETURN_IF_ERROR(file.create_named(target.string(), options, path));
  for (const std::string_view part : parts) {
    if (Status written = file.write(part); !written.ok()) return written;
  }
  return file.commit();
}

Status sync_file(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0 || ::fsync(fd) != 0) {
    const Status failed = io_error_from_errno("cannot sync " + path);
    if (fd >= 0) ::close(fd);
    return failed;
  }
  ::close(fd);
  return Status::Ok();
}

Status AtomicDirectory::create(const std::string& target) {
  target_ = target;
  return temp_.create_beside(target);
}

Status AtomicDirectory::commit(bool sync, const std::string& what) {
  if (sync) OUTCORE_RETURN_IF_ERROR(sync_directory(temp_.path()));
  std::error_code ec;
  std::string displaced;
  if (fs::exists(fs::symlink_status(target_, ec))) {
    // A leftover of an interrupted run of a process with the same pid must
    // not block the swap.
    const std::string base = target_ + ".replaced-" + std::to_string(::getpid());
    displaced = base;
    for (int attempt = 1; fs::exists(displaced, ec); ++attempt)
      displaced = base + "-" + std::to_string(attempt);
    fs::rename(target_, displaced, ec);
    if (ec) return io_error("cannot move the existing " + target_ + " aside: " + ec.message());
  }
  fs::rename(temp_.path(), target_, ec);
  if (ec) {
    if (!displaced.empty()) fs::rename(displaced, target_, ec);
    return io_error("cannot rename the new " + what + " into " + target_ + ": " + ec.message());
  }
  temp_.release();
  if (sync) OUTCORE_RETURN_IF_ERROR(sync_directory(fs::path(target_).parent_path().string()));
  if (!displaced.empty()) fs::remove_all(displaced, ec);
  return Status::Ok();
}

}  // namespace outcore
