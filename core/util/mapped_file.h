// MappedFile: a whole file mapped read-only (mmap), for reading files that are
// checked and parsed once (subtree tier entries): the kernel's page cache holds
// the bytes, not this process's heap.
//
// Thread-safety: open() is reentrant; a mapped file is immutable and may be
// read from many threads.
#pragma once

#include <cstddef>
#include <span>
#include <string>

#include "core/util/status.h"

namespace outcore {

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

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace outcore
