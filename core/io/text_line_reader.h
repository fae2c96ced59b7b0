// TextLineReader: reads a file through one fixed-size buffer, as text lines
// (with line numbers, CRLF or LF endings) and, for formats such as binary PLY
// whose text header is followed by raw data, as raw bytes from the same point.
// Memory stays bounded whatever the file's size: the buffer only grows when a
// single line is longer than it, and never beyond kMaxLineBytes.
//
// Thread-safety: one thread at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace outcore {

enum class NumberParse { kOk, kGarbled, kTooLarge };

// Parses all of token as a real number correctly rounded to T (float or
// double), with std::from_chars (fast, locale-independent), also accepting the
// leading '+' that strtod allows. "nan" and "inf" parse; callers decide whether
// they are allowed. A magnitude beyond T's range is kTooLarge; one too small
// becomes zero or a denormal, as with strtod.
template <class T>
NumberParse parse_real(std::string_view token, T& value);
extern template NumberParse parse_real<float>(std::string_view, float&);
extern template NumberParse parse_real<double>(std::string_view, double&);

// OK if path names a regular file this process can open for reading; else the
// same errors as TextLineReader::open(). Lets a source fail at open time.
Status check_readable_file(const std::string& path);

class TextLineReader {
 public:
  static constexpr std::size_t kBufferBytes = std::size_t{1} << 20;
  static constexpr std::size_t kMaxLineBytes = std::size_t{64} << 20;

  TextLineReader() = default;
  ~TextLineReader();
  TextLineReader(const TextLineReader&) = delete;
  TextLineReader& operator=(const TextLineReader&) = delete;

  // NOT_FOUND "path: No such file or directory" if the file is missing,
  // INVALID_ARGUMENT for a directory, IO_ERROR for other refusals.
  Status open(const std::string& path);

  // The next line without its "\n" or "\r\n"; false at the end of the file or
  // on an error (then status() says which). The view is valid until the next call.
  bool next_line(std::string_view& line);

  // Copies the next n bytes; false if the file ends first or on an error.
  bool read_bytes(void* dst, std::size_t n) {
    if (static_cast<std::size_t>(end_ - begin_) >= n) {
      std::memcpy(dst, begin_, n);
      begin_ += n;
      return true;
    }
    return read_bytes_slow(static_cast<char*>(dst), n);
  }
  // Skips the next n bytes; false if the file ends first or on an error.
  bool skip_bytes(std::uint64_t n);

  // 1-based number of the line last returned by next_line().
  std::uint64_t line_number() const { return line_number_; }
  // OK unless reading failed (the end of the file is not an error).
  const Status& status() const { return status_; }
  const std::string& path() const { return path_; }

 private:
  bool read_bytes_slow(char* dst, std::size_t n);
  // Moves the unread bytes to the front and reads more after them; false when
  // nothing more could be read (end of file or error).
  bool refill();

  std::string path_;
  int fd_ = -1;
  std::vector<char> buffer_;
  char* begin_ = nullptr;  // first unread byte
  char* end_ = nullptr;    // one past the last byte read from the file
  bool at_eof_ = false;
  std::uint64_t line_number_ = 0;
  Status status_;
};

}  // namespace outcore
