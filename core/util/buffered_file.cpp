#include "core/util/buffered_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstring>

namespace outcore {

Status write_fully(int fd, const char* data, std::size_t bytes, const std::string& path) {
  while (bytes > 0) {
    const ssize_t put = ::write(fd, data, bytes);
    if (put < 0) {
      if (errno == EINTR) continue;
      return io_error_from_errno("cannot write " + path);
    }
    data += put;
    bytes -= static_cast<std::size_t>(put);
  }
  return Status::Ok();
}

BufferedFileWriter::~BufferedFileWriter() {
  if (writer_thread_.joinable()) {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    cv_.notify_all();
    writer_thread_.join();
  }
  if (fd_ >= 0) ::close(fd_);
}

Status BufferedFileWriter::create(const std::string& path, std::size_t buffer_bytes, bool asynchronous) {
  path_ = path;
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd_ < 0) return io_error_from_errno("cannot create " + path);
  capacity_ = buffer_bytes;
  buffer_.reserve(buffer_bytes);
  written_ = 0;
  if (asynchronous) {
    in_flight_.reserve(buffer_bytes);
    writer_thread_ = std::thread([this] { background_loop(); });
  }
  return Status::Ok();
}

void BufferedFileWriter::background_loop() {
  std::unique_lock lock(mutex_);
  while (true) {
    cv_.wait(lock, [&] { return has_work_ || stopping_; });
    if (!has_work_) return;
    lock.unlock();
    Status status = write_fully(fd_, in_flight_.data(), in_flight_.size(), path_);
    if (status.ok()) stream_to_disk(in_flight_.size());
    lock.lock();
    if (background_status_.ok()) background_status_ = status;
    has_work_ = false;
    cv_.notify_all();
  }
}

// Without this the kernel starts writeback only at its dirty threshold, so the
// disk idles while the packer computes, then the whole backlog (gigabytes)
// waits in the final fsync. Instead each buffer's pages are queued for
// writeback as soon as they are written (SYNC_FILE_RANGE_WRITE does not wait),
// and the buffer before it, whose writeback has had a whole buffer's time to
// finish, is waited for and dropped from the page cache: dirty pages stay
// bounded by two buffers and the disk works all the time. Best effort: an
// error here (a file system without sync_file_range) changes nothing, since
// close(sync) fsyncs anyway.
void BufferedFileWriter::stream_to_disk(std::size_t bytes) {
  const uint64_t begin = background_offset_;
  background_offset_ += bytes;
  ::sync_file_range(fd_, static_cast<off64_t>(begin), static_cast<off64_t>(bytes), SYNC_FILE_RANGE_WRITE);
  if (begin > streamed_) {
    const uint64_t length = begin - streamed_;
    ::sync_file_range(fd_, static_cast<off64_t>(streamed_), static_cast<off64_t>(length),
                      SYNC_FILE_RANGE_WAIT_BEFORE | SYNC_FILE_RANGE_WRITE | SYNC_FILE_RANGE_WAIT_AFTER);
    ::posix_fadvise(fd_, static_cast<off_t>(streamed_), static_cast<off_t>(length), POSIX_FADV_DONTNEED);
    streamed_ = begin;
  }
}

Status BufferedFileWriter::wait_for_background_write() {
  if (!writer_thread_.joinable()) return Status::Ok();
  std::unique_lock lock(mutex_);
  if (has_work_) {
    const auto start = std::chrono::steady_clock::now();
    cv_.wait(lock, [&] { return !has_work_; });
    wait_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return background_status_;
}

Status BufferedFileWriter::flush_buffer() {
  if (writer_thread_.joinable()) {
    OUTCORE_RETURN_IF_ERROR(wait_for_background_write());
    written_ += buffer_.size();
    {
      std::lock_guard lock(mutex_);
      in_flight_.swap(buffer_);
      has_work_ = !in_flight_.empty();
    }
    cv_.notify_all();
    buffer_.clear();
    return Status::Ok();
  }
  OUTCORE_RETURN_IF_ERROR(write_fully(fd_, buffer_.data(), buffer_.size(), path_));
  written_ += buffer_.size();
  buffer_.clear();
  return Status::Ok();
}

Status BufferedFileWriter::append(const void* data, std::size_t bytes) {
  const char* src = static_cast<const char*>(data);
  if (buffer_.size() + bytes > capacity_) {
    OUTCORE_RETURN_IF_ERROR(flush_buffer());
    if (bytes >= capacity_) {
      OUTCORE_RETURN_IF_ERROR(wait_for_background_write());
      OUTCORE_RETURN_IF_ERROR(write_fully(fd_, src, bytes, path_));
      written_ += bytes;
      // The background thread is idle here; keep its file offset in step.
      background_offset_ += bytes;
      return Status::Ok();
    }
  }
  buffer_.insert(buffer_.end(), src, src + bytes);
  return Status::Ok();
}

Status BufferedFileWriter::pad_to(uint64_t alignment) {
  static const char kZeros[4096] = {};
  uint64_t remainder = size() % alignment;
  if (remainder == 0) return Status::Ok();
  uint64_t padding = alignment - remainder;
  while (padding > 0) {
    const std::size_t step = static_cast<std::size_t>(std::min<uint64_t>(padding, sizeof kZeros));
    OUTCORE_RETURN_IF_ERROR(append(kZeros, step));
    padding -= step;
  }
  return Status::Ok();
}

Status BufferedFileWriter::close(bool sync) {
  if (fd_ < 0) return Status::Ok();
  Status status = flush_buffer();
  if (status.ok()) status = wait_for_background_write();
  if (status.ok() && sync && ::fsync(fd_) != 0) status = io_error_from_errno("cannot sync " + path_);
  if (::close(fd_) != 0 && status.ok()) status = io_error_from_errno("cannot close " + path_);
  fd_ = -1;
  buffer_ = {};
  return status;
}

Status read_file_chunks(const std::string& path, std::size_t record_bytes, std::size_t chunk_bytes,
                        const std::function<Status(const char* data, std::size_t bytes)>& fn) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error_from_errno("cannot open " + path);
  posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
  chunk_bytes = std::max(record_bytes, chunk_bytes / record_bytes * record_bytes);
  std::vector<char> buffer(chunk_bytes);
  std::size_t filled = 0;
  Status status;
  while (status.ok()) {
    const ssize_t got = ::read(fd, buffer.data() + filled, chunk_bytes - filled);
    if (got < 0) {
      if (errno == EINTR) continue;
      status = io_error_from_errno("cannot read " + path);
      break;
    }
    filled += static_cast<std::size_t>(got);
    const bool at_end = got == 0;
    if (filled == chunk_bytes || (at_end && filled > 0)) {
      if (filled % record_bytes != 0) {
        status = data_loss(path + " ends in a partial record");
        break;
      }
      status = fn(buffer.data(), filled);
      filled = 0;
    }
    if (at_end) break;
  }
  ::close(fd);
  return status;
}

Status sync_directory(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return io_error_from_errno("cannot open directory " + path);
  Status status;
  if (::fsync(fd) != 0) status = io_error_from_errno("cannot sync directory " + path);
  ::close(fd);
  return status;
}

}  // namespace outcore
