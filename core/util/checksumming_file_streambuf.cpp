#include "core/util/checksumming_file_streambuf.h"

namespace outcore {
namespace {
constexpr std::size_t kBufferBytes = std::size_t{1} << 16;
}  // namespace

Status ChecksummingFileStreambuf::create(const std::string& path) {
  // The stream buffer batches cereal's small writes; the file writer's own
  // buffer batches the system calls.
  status_ = file_.create(path, std::size_t{1} << 20);
  buffer_.resize(kBufferBytes);
  setp(buffer_.data(), buffer_.data() + buffer_.size());
  return status_;
}

bool ChecksummingFileStreambuf::drain() {
  const std::size_t pending = static_cast<std::size_t>(pptr() - pbase());
  if (pending > 0 && status_.ok()) {
    checksum_.update(pbase(), pending);
    status_ = file_.append(pbase(), pending);
  }
  setp(buffer_.data(), buffer_.data() + buffer_.size());
  return status_.ok();
}

ChecksummingFileStreambuf::int_type ChecksummingFileStreambuf::overflow(int_type ch) {
  if (!drain()) return traits_type::eof();
  if (!traits_type::eq_int_type(ch, traits_type::eof())) {
    *pptr() = traits_type::to_char_type(ch);
    pbump(1);
  }
  return traits_type::not_eof(ch);
}

std::streamsize ChecksummingFileStreambuf::xsputn(const char* data, std::streamsize count) {
  const auto bytes = static_cast<std::size_t>(count);
  if (bytes <= static_cast<std::size_t>(epptr() - pptr())) {
    traits_type::copy(pptr(), data, bytes);
    pbump(static_cast<int>(count));
    return count;
  }
  // Large blocks (a tree's arrays) go straight to the file writer.
  if (!drain()) return 0;
  checksum_.update(data, bytes);
  status_ = file_.append(data, bytes);
  return status_.ok() ? count : 0;
}

int ChecksummingFileStreambuf::sync() {
  return drain() ? 0 : -1;
}

uint64_t ChecksummingFileStreambuf::checksum() {
  drain();
  return checksum_.digest();
}

Status ChecksummingFileStreambuf::append_unchecked(const void* data, std::size_t bytes) {
  if (!drain()) return status_;
  status_ = file_.append(data, bytes);
  return status_;
}

Status ChecksummingFileStreambuf::close() {
  drain();
  const Status closed = file_.close(/*sync=*/false);
  if (!status_.ok()) return status_;
  return closed;
}

}  // namespace outcore
