// ChecksummingFileStreambuf: an output stream buffer that writes to a new file
// (BufferedFileWriter) and keeps the XXH3-64 checksum of every byte written,
// so a serialiser (cereal) can stream a large structure to disk and the file
// can end with its own checksum without a second copy in memory.
//
// Thread-safety: one writer at a time.
#pragma once

#include <cstdint>
#include <streambuf>
#include <string>
#include <vector>

#include "core/util/buffered_file.h"
#include "core/util/checksum.h"
#include "core/util/status.h"

namespace outcore {

class ChecksummingFileStreambuf final : public std::streambuf {
 public:
  // Creates `path` (it must not exist).
  Status create(const std::string& path);
  // The checksum of everything written so far (flushes this buffer first).
  uint64_t checksum();
  // Bytes written so far.
  uint64_t size() const { return file_.size() + static_cast<uint64_t>(pptr() - pbase()); }
  // Appends bytes that are not part of the checksum (a trailer holding it).
  Status append_unchecked(const void* data, std::size_t bytes);
  // Flushes and closes; the first error since create(), if any.
  Status close();

 protected:
  int_type overflow(int_type ch) override;
  std::streamsize xsputn(const char* data, std::streamsize count) override;
  int sync() override;

 private:
  bool drain();

  BufferedFileWriter file_;
  Checksum64 checksum_;
  std::vector<char> buffer_;
  Status status_;
};

}  // namespace outcore
