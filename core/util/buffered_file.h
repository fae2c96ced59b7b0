// BufferedFileWriter / read_file_chunks: sequential file I/O with a fixed-size
// buffer, for spill files and brick data where the whole file never fits in
// memory. Writes go through write(2) (not mmap) so the page cache, not this
// process, holds what was written. write_fully: one whole write(2) loop.
//
// Thread-safety: a writer is used by one thread at a time (an asynchronous
// writer owns one background thread of its own).
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/util/status.h"

namespace outcore {

// Writes all `bytes` at `data` to `fd` (retrying short writes and EINTR);
// IO_ERROR "cannot write PATH: reason" otherwise.
Status write_fully(int fd, const char* data, std::size_t bytes, const std::string& path);

class BufferedFileWriter {
 public:
  BufferedFileWriter() = default;
  ~BufferedFileWriter();
  BufferedFileWriter(const BufferedFileWriter&) = delete;
  BufferedFileWriter& operator=(const BufferedFileWriter&) = delete;

  // Creates a new file (fails if it exists) with a buffer of buffer_bytes.
  // With asynchronous, a second buffer is filled while a background thread
  // writes the first, so the kernel's copy overlaps the caller's work; the
  // background thread also streams the data to the disk as it goes (see
  // background_loop), for files written once and not read back soon.
  Status create(const std::string& path, std::size_t buffer_bytes, bool asynchronous = false);
  Status append(const void* data, std::size_t bytes);
  // Appends zero bytes up to the next multiple of alignment.
  Status pad_to(uint64_t alignment);
  // Bytes appended so far (the offset of the next append).
  uint64_t size() const { return written_ + buffer_.size(); }
  // Flushes; with sync, also fsync()s so the data is durable before a rename.
  Status close(bool sync);
  const std::string& path() const { return path_; }
  // Seconds append() spent waiting for the background write (the disk lagging).
  double wait_seconds() const { return wait_seconds_; }

 private:
  Status flush_buffer();
  Status wait_for_background_write();
  void background_loop();
  void stream_to_disk(std::size_t bytes);

  std::string path_;
  int fd_ = -1;
  std::vector<char> buffer_;
  std::size_t capacity_ = 0;
  uint64_t written_ = 0;
  double wait_seconds_ = 0.0;

  // Asynchronous mode: in_flight_ is being written by writer_thread_.
  std::thread writer_thread_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<char> in_flight_;
  bool has_work_ = false;
  bool stopping_ = false;
  Status background_status_;
  // Writeback window of the background thread: [streamed_, background_offset_)
  // has been handed to the kernel for writing but not yet waited for.
  uint64_t background_offset_ = 0;
  uint64_t streamed_ = 0;
};

// Reads path sequentially in chunks of at most chunk_bytes (a multiple of
// record_bytes) and hands each chunk to fn. A file whose size is not a
// multiple of record_bytes is DATA_LOSS.
Status read_file_chunks(const std::string& path, std::size_t record_bytes, std::size_t chunk_bytes,
                        const std::function<Status(const char* data, std::size_t bytes)>& fn);

// fsync() a directory so a rename inside it is durable.
Status sync_directory(const std::string& path);

}  // namespace outcore
