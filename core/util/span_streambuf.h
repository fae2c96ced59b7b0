// SpanStreambuf: an input stream buffer over bytes someone else owns (a mapped
// file, a string), so cereal can read them without a copy (std::ispanstream
// is C++23).
//
// Thread-safety: one reader at a time; the bytes must outlive the buffer.
#pragma once

#include <cstddef>
#include <span>
#include <streambuf>

namespace outcore {

class SpanStreambuf final : public std::streambuf {
 public:
  explicit SpanStreambuf(std::span<const char> bytes) {
    // The get area is never written through: streambuf only offers char*.
    char* begin = const_cast<char*>(bytes.data());
    setg(begin, begin, begin + bytes.size());
  }
  // Bytes not read yet.
  std::size_t remaining() const { return static_cast<std::size_t>(egptr() - gptr()); }
};

}  // namespace outcore
