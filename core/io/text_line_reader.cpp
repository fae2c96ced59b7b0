#include "core/io/text_line_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <system_error>
#include <type_traits>

#include "core/util/file_type.h"

namespace outcore {

namespace {

// Opens path for reading into fd (-1 on failure, closed by the caller).
Status open_for_reading(const std::string& path, int& fd) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer
  // for ever, before there is any file type to check.
  fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return io_error_from_errno(path);
  struct stat info;
  if (::fstat(fd, &info) != 0) return io_error_from_errno(path);
  // open() succeeds on a directory, a FIFO or a device; reading them fails
  // late with a less helpful message, blocks, or never ends.
  if (S_ISDIR(info.st_mode)) return invalid_argument(path + ": is a directory, not a file");
  if (!S_ISREG(info.st_mode)) {
    return invalid_argument(path + ": is " + file_type_name(info.st_mode) + ", not a regular file");
  }
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0) return io_error_from_errno(path);
  return Status::Ok();
}

}  // namespace

template <class T>
NumberParse parse_real(std::string_view token, T& value) {
  const char* first = token.data();
  const char* last = first + token.size();
  if (last - first > 1 && *first == '+' && first[1] != '-' && first[1] != '+') ++first;
  auto [end, error] = std::from_chars(first, last, value);
  if (error == std::errc::result_out_of_range && end == last) {
    // Too large or too small in magnitude; only the first is an error.
    if constexpr (std::is_same_v<T, float>) {
      double wide = 0;
      if (std::from_chars(first, last, wide).ec == std::errc()) {
        if (std::fabs(wide) > 1.0) return NumberParse::kTooLarge;
        value = static_cast<float>(wide);  // zero or a denormal
        return NumberParse::kOk;
      }
    }
    // Beyond double as well: the exponent's sign tells which way.
    const std::string_view digits(first, static_cast<std::size_t>(last - first));
    if (digits.find("e-") == std::string_view::npos && digits.find("E-") == std::string_view::npos) {
      return NumberParse::kTooLarge;
    }
    value = *first == '-' ? -T{0} : T{0};
    return NumberParse::kOk;
  }
  if (error != std::errc() || end != last) return NumberParse::kGarbled;
  return NumberParse::kOk;
}
template NumberParse parse_real<float>(std::string_view, float&);
template NumberParse parse_real<double>(std::string_view, double&);

Status check_readable_file(const std::string& path) {
  int fd = -1;
  Status status = open_for_reading(path, fd);
  if (fd >= 0) ::close(fd);
  return status;
}

TextLineReader::~TextLineReader() {
  if (fd_ >= 0) ::close(fd_);
}

Status TextLineReader::open(const std::string& path) {
  if (fd_ >= 0) ::close(fd_);
  path_ = path;
  Status opened = open_for_reading(path, fd_);
  if (!opened.ok()) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    return opened;
  }
  buffer_.resize(kBufferBytes);
  begin_ = end_ = buffer_.data();
  at_eof_ = false;
  line_number_ = 0;
  status_ = Status::Ok();
  return Status::Ok();
}

bool TextLineReader::refill() {
  if (at_eof_ || !status_.ok() || fd_ < 0) return false;
  const std::size_t unread = static_cast<std::size_t>(end_ - begin_);
  if (begin_ != buffer_.data()) std::memmove(buffer_.data(), begin_, unread);
  begin_ = buffer_.data();
  end_ = begin_ + unread;
  const std::size_t space = buffer_.size() - unread;
  for (;;) {
    const ssize_t got = ::read(fd_, end_, space);
    if (got > 0) {
      end_ += got;
      return true;
    }
    if (got == 0) {
      at_eof_ = true;
      return false;
    }
    if (errno == EINTR) continue;
    status_ = io_error_from_errno(path_);
    return false;
  }
}

bool TextLineReader::next_line(std::string_view& line) {
  if (!status_.ok() || fd_ < 0) return false;
  std::size_t scanned = 0;  // bytes after begin_ already known to hold no '\n'
  for (;;) {
    const std::size_t unread = static_cast<std::size_t>(end_ - begin_);
    char* newline = static_cast<char*>(std::memchr(begin_ + scanned, '\n', unread - scanned));
    const char* line_end = newline;
    if (newline == nullptr) {
      scanned = unread;
      if (at_eof_) {
        if (unread == 0) return false;
        line_end = end_;  // the last line has no newline
      } else {
        if (unread == buffer_.size()) {
          // One line fills the whole buffer: grow it, within reason, so that
          // the line can be returned as one view.
          if (buffer_.size() >= kMaxLineBytes) {
            status_ = invalid_argument(path_ + ":" + std::to_string(line_number_ + 1) +
                                       ": line longer than " + std::to_string(kMaxLineBytes >> 20) + " MiB");
            return false;
          }
          const std::size_t offset = static_cast<std::size_t>(begin_ - buffer_.data());
          buffer_.resize(std::min(buffer_.size() * 2, kMaxLineBytes));
          begin_ = buffer_.data() + offset;
          end_ = begin_ + unread;
        }
        if (!refill() && !status_.ok()) return false;
        continue;
      }
    }
    std::size_t length = static_cast<std::size_t>(line_end - begin_);
    if (length > 0 && begin_[length - 1] == '\r') --length;
    line = std::string_view(begin_, length);
    begin_ = newline != nullptr ? newline + 1 : end_;
    ++line_number_;
    return true;
  }
}

bool TextLineReader::read_bytes_slow(char* dst, std::size_t n) {
  for (;;) {
    const std::size_t take = std::min(n, static_cast<std::size_t>(end_ - begin_));
    std::memcpy(dst, begin_, take);
    begin_ += take;
    dst += take;
    n -= take;
    if (n == 0) return true;
    if (!refill()) return false;
  }
}

bool TextLineReader::skip_bytes(std::uint64_t n) {
  for (;;) {
    const std::uint64_t take = std::min<std::uint64_t>(n, static_cast<std::uint64_t>(end_ - begin_));
    begin_ += take;
    n -= take;
    if (n == 0) return true;
    if (!refill()) return false;
  }
}

}  // namespace outcore
