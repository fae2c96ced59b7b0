// Test helpers for .npz readers: ZIP archives as numpy.savez and
// savez_compressed write them (stored or deflated members, optionally with
// ZIP64 extra fields), and .npy images of arrays, built in memory.
//
// Thread-safety: pure functions (test code).
#pragma once

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <string>
#include <vector>

namespace outcore::testing {

inline void put(std::string& out, uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out += static_cast<char>((value >> (8 * i)) & 0xff);
}

inline std::string deflated(const std::string& data) {
  z_stream zs{};
  EXPECT_EQ(deflateInit2(&zs, 6, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&zs, data.size()), '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

struct Entry {
  std::string name, data;
  bool deflate = false;
  bool zip64 = false;  // sizes and offset in a ZIP64 extra field
};

// A ZIP archive as numpy.savez / savez_compressed write them.
inline std::string zip_of(const std::vector<Entry>& entries) {
  std::string out, directory;
  for (const Entry& e : entries) {
    const std::string body = e.deflate ? deflated(e.data) : e.data;
    const uint32_t crc =
        crc32(0, reinterpret_cast<const Bytef*>(e.data.data()), static_cast<uInt>(e.data.size()));
    const uint64_t offset = out.size();
    put(out, 0x04034b50, 4), put(out, 20, 2), put(out, 0, 2), put(out, e.deflate ? 8 : 0, 2), put(out, 0, 4);
    put(out, crc, 4), put(out, body.size(), 4), put(out, e.data.size(), 4);
    put(out, e.name.size(), 2), put(out, 0, 2);
    out += e.name + body;
    std::string extra;
    if (e.zip64)
      put(extra, 1, 2), put(extra, 24, 2), put(extra, e.data.size(), 8), put(extra, body.size(), 8),
          put(extra, offset, 8);
    put(directory, 0x02014b50, 4), put(directory, 45, 2), put(directory, 20, 2), put(directory, 0, 2);
    put(directory, e.deflate ? 8 : 0, 2), put(directory, 0, 4), put(directory, crc, 4);
    const uint64_t saturated = 0xffffffffu;
    put(directory, e.zip64 ? saturated : body.size(), 4),
        put(directory, e.zip64 ? saturated : e.data.size(), 4);
    put(directory, e.name.size(), 2), put(directory, extra.size(), 2), put(directory, 0, 2);
    put(directory, 0, 2), put(directory, 0, 2), put(directory, 0, 4),
        put(directory, e.zip64 ? saturated : offset, 4);
    directory += e.name + extra;
  }
  const uint64_t directory_offset = out.size();
  out += directory;
  put(out, 0x06054b50, 4), put(out, 0, 4), put(out, entries.size(), 2), put(out, entries.size(), 2);
  put(out, directory.size(), 4), put(out, directory_offset, 4), put(out, 0, 2);
  return out;
}

// A .npy (format 1.0) image: `descr` such as "<f4", `shape` as numpy
// prints it ("(4, 3)"), `data` the raw bytes in the order `fortran` says.
inline std::string npy_image(const std::string& descr, const std::string& shape, const std::string& data,
                             bool fortran = false) {
  std::string dict = "{'descr': '" + descr + "', 'fortran_order': " + (fortran ? "True" : "False") +
                     ", 'shape': " + shape + ", }";
  while ((10 + dict.size() + 1) % 64 != 0) dict += ' ';
  dict += '\n';
  std::string out("\x93NUMPY\x01\x00", 8);
  put(out, dict.size(), 2);
  return out + dict + data;
}

// The bytes of a vector of plain values (array data for npy_image).
template <class T>
std::string raw_bytes(const std::vector<T>& values) {
  return std::string(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
}

}  // namespace outcore::testing
