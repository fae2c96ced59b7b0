// How many pages of a range this process has in its page tables
// (/proc/self/pagemap's "present" bit, readable without privileges): what
// the tests of page release and population count.
//
// Thread-safety: pure function (reads /proc).
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace outcore::testing {

inline constexpr std::size_t kTestPageBytes = 4096;

// Present pages of [data, data + bytes); SIZE_MAX when pagemap cannot be read.
inline std::size_t present_pages(const void* data, std::size_t bytes) {
  const int fd = ::open("/proc/self/pagemap", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return SIZE_MAX;
  const auto first = reinterpret_cast<uintptr_t>(data) / kTestPageBytes;
  const std::size_t pages = (bytes + kTestPageBytes - 1) / kTestPageBytes;
  std::vector<uint64_t> entries(pages);
  const ssize_t got = ::pread(fd, entries.data(), pages * sizeof(uint64_t), static_cast<off_t>(first * 8));
  ::close(fd);
  if (got != static_cast<ssize_t>(pages * sizeof(uint64_t))) return SIZE_MAX;
  std::size_t present = 0;
  for (const uint64_t e : entries) present += (e >> 63) & 1;
  return present;
}

}  // namespace outcore::testing
