// MappedFile: a whole file mapped read-only (mmap) and read in place (subtree
// tier entries): the kernel's page cache holds the bytes, not this process's
// heap, and unmapping gives them back to it. Pages are mapped as they are
// first read (a reader that touches only part of a file pays only for that
// part); will_need() asks the kernel to read the whole file ahead for a
// reader that will touch all of it. identity() tells whether a path still
// names the same, unmodified file.
//
// Whoever maps a file must not let it be truncated or written in place while
// mapped (reading a page past a truncation raises SIGBUS); the subtree tier
// only ever replaces files by rename or unlinks them, which leaves existing
// mappings intact.
//
// Thread-safety: open() is reentrant; a mapped file is immutable and may be
// read from many threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/util/status.h"

namespace outcore {

// Which file a path named, and its version: equal identities mean the same
// inode, unchanged in size and modification time.
struct FileIdentity {
  uint64_t device = 0;
  uint64_t inode = 0;
  uint64_t size = 0;
  int64_t modified_ns = 0;

  bool operator==(const FileIdentity&) const = default;
};

// The identity of the file at `path`: NOT_FOUND when there is none.
Expected<FileIdentity> file_identity(const std::string& path);

class MappedFile {
 public:
  MappedFile() = default;
  ~MappedFile();
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  // NOT_FOUND when the file does not exist, IO_ERROR for other failures.
  // An empty file maps to empty bytes.
  static Expected<MappedFile> open(const std::string& path);

  std::span<const char> bytes() const { return {data_, size_}; }
  // A hint (MADV_WILLNEED) that all of the file is about to be read.
  void will_need() const;
  // Unmaps the pages read so far (MADV_DONTNEED) but keeps the mapping: they
  // leave this process's RSS (the page cache keeps them) and are faulted in
  // again, with the same bytes, when next read. Cheaper than unmapping and
  // mapping again: no mapping changes, so other threads' page faults are not
  // held up by the process's mapping lock.
  void release_pages() const;
  // The mapped file's identity when it was opened.
  const FileIdentity& identity() const { return identity_; }

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
  FileIdentity identity_;
};

}  // namespace outcore
