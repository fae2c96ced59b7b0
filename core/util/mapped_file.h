// MappedFile: a whole file in memory of its own mapping, read in place, in
// one of two kinds:
//
// - open(): the file mapped read-only (mmap). The kernel's page cache holds
//   the bytes, not this process's heap; pages are mapped as they are first
//   read. Whoever maps a file this way must be sure nobody truncates or
//   writes it in place while mapped: reading a page past a truncation raises
//   SIGBUS, and bytes written in place show through (MAP_PRIVATE copies only
//   on our own writes).
// - copy(): the file read into a private anonymous mapping. The bytes are
//   this process's own: the file may then be truncated, overwritten or
//   deleted without affecting them (the subtree tier, whose directory other
//   processes and users may touch). Unmapping still gives the memory back to
//   the system, not to the allocator. The mapping's length, capacity(), is
//   the size rounded up to kCopyCapacityStep, so read_again() can later read
//   a somewhat larger file, or another file, into it; only the pages of
//   bytes() are ever populated (the rest is address space, not memory).
//
// release_pages() drops the pages from the RSS but keeps the mapping, so the
// next read maps no memory (no write on the process's mapping lock).
// identity() tells whether a path still names the same, unmodified file.
//
// Thread-safety: open() and copy() are reentrant; the bytes may be read from
// many threads, and change only by read_again(), which needs its caller to
// be their only user (the subtree tier makes sure of it).
#pragma once

#include <sys/stat.h>

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
// The identity of a file already stat()ed (or fstat()ed).
FileIdentity identity_of(const struct stat& info);

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
  // The file's bytes read into a private anonymous mapping. NOT_FOUND when
  // the file does not exist; IO_ERROR for other failures, among them a file
  // that shrank while being read.
  static Expected<MappedFile> copy(const std::string& path);
  // copy()'s capacity is its size rounded up to a multiple of this.
  static constexpr std::size_t kCopyCapacityStep = std::size_t{256} << 10;

  // A copy() only: reads `path` (the same file again, or another one) into
  // the same memory (no mapping changes), e.g. after release_pages(); bytes()
  // then has the file's size. FAILED_PRECONDITION when the file is larger
  // than capacity() (make a new copy instead), NOT_FOUND / IO_ERROR as
  // copy(). Nobody may read the bytes meanwhile. On failure the bytes are
  // undefined. `pages_kept`: the pages of the bytes() before the call were
  // not released since they were written (a copy taken out of a
  // PageReleaseQueue before its batch): they are written over as they are,
  // and those past the new size released, so the RSS holds the new bytes'
  // pages only. Otherwise they are taken as released and populated first.
  Status read_again(const std::string& path, bool pages_kept = false);

  std::span<const char> bytes() const { return {data_, size_}; }
  // The mapping's length (copies: see above; file mappings: their size).
  std::size_t capacity() const { return capacity_; }
  bool is_copy() const { return copy_; }
  // Unmaps the pages read so far (MADV_DONTNEED) but keeps the mapping: they
  // leave this process's RSS. A file mapping faults them in again, with the
  // same bytes (the page cache keeps them), when next read; a copy's pages
  // then read as zeros until read_again(). Cheaper than unmapping and
  // mapping again: no mapping changes, so other threads' page faults are not
  // held up by the process's mapping lock.
  void release_pages() const;
  // The file's identity when it was opened or last read.
  const FileIdentity& identity() const { return identity_; }

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
  std::size_t capacity_ = 0;  // mapped bytes from data_
  FileIdentity identity_;
  bool copy_ = false;
};

}  // namespace outcore
