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

}  // namespace

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
  const fs::path directory = target.has_parent_path() ? target.parent_path() : fs::path(".");
  // Unique among threads (counter) and processes (pid); a stale one of an
  // earlier process with our pid is skipped (O_EXCL).
  static std::atomic<uint64_t> sequence{0};
  std::string temp;
  int fd = -1;
  for (int attempt = 0; attempt < 100 && fd < 0; ++attempt) {
    temp = (directory / ("." + target.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                         std::to_string(sequence.fetch_add(1))))
               .string();
    fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC,
                options.mode >= 0 ? static_cast<mode_t>(options.mode) : 0666);
    if (fd < 0 && errno != EEXIST) break;
  }
  if (fd < 0) return io_error_from_errno("cannot create a temporary file beside " + path);
  const auto fail = [&](const std::string& what) {
    const Status failed = io_error_from_errno(what);
    ::close(fd);
    ::unlink(temp.c_str());
    return failed;
  };
  for (const std::string_view part : parts) {
    if (Status written = write_fully(fd, part.data(), part.size(), path); !written.ok()) {
      ::close(fd);
      ::unlink(temp.c_str());
      return written;
    }
  }
  // The umask may have cleared bits an explicit mode asks for.
  if (options.mode >= 0 && ::fchmod(fd, static_cast<mode_t>(options.mode)) != 0) {
    return fail("cannot set the mode of " + temp);
  }
  if (options.sync && ::fsync(fd) != 0) return fail("cannot sync " + path);
  if (::close(fd) != 0) {
    const Status failed = io_error_from_errno("cannot write " + path);
    ::unlink(temp.c_str());
    return failed;
  }
  if (::rename(temp.c_str(), target.c_str()) != 0) {
    const Status failed = io_error_from_errno("cannot rename " + temp + " to " + target.string());
    ::unlink(temp.c_str());
    return failed;
  }
  return Status::Ok();
}

}  // namespace outcore
