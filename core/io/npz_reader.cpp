#include "core/io/npz_reader.h"

#include <zlib.h>

#include <cstdint>
#include <limits>

#include "core/io/npy.h"

namespace outcore {
namespace {

constexpr uint32_t kEndOfDirectory = 0x06054b50;
constexpr uint32_t kZip64Locator = 0x07064b50;
constexpr uint32_t kZip64End = 0x06064b50;
constexpr uint32_t kDirectoryEntry = 0x02014b50;
constexpr uint32_t kLocalHeader = 0x04034b50;
constexpr uint16_t kZip64Extra = 0x0001;
constexpr uint32_t kSaturated = 0xffffffffu;

// Little-endian reads at an offset, bounds-checked by the caller.
uint64_t le(std::string_view b, uint64_t at, int bytes) {
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= uint64_t{static_cast<uint8_t>(b[at + i])} << (8 * i);
  return v;
}

struct Member {
  std::string name;
  uint16_t flags = 0, method = 0;
  uint32_t crc = 0;
  uint64_t compressed = 0, size = 0, local_offset = 0;
};

struct Directory {
  uint64_t entries = 0, offset = 0, size = 0;
};

Expected<Directory> find_directory(std::string_view b, const std::string& name) {
  if (b.size() < 22) return invalid_argument(name + " is not a .npz (ZIP) archive: too short");
  const uint64_t lowest = b.size() >= 22 + 65535 ? b.size() - 22 - 65535 : 0;
  for (uint64_t at = b.size() - 22 + 1; at-- > lowest;) {
    if (le(b, at, 4) != kEndOfDirectory) continue;
    Directory d{le(b, at + 10, 2), le(b, at + 16, 4), le(b, at + 12, 4)};
    if ((d.entries == 0xffff || d.offset == kSaturated || d.size == kSaturated) && at >= 20 &&
        le(b, at - 20, 4) == kZip64Locator) {
      const uint64_t end64 = le(b, at - 20 + 8, 8);
      if (end64 > b.size() || b.size() - end64 < 56 || le(b, end64, 4) != kZip64End)
        return invalid_argument(name + ": broken ZIP64 end of central directory");
      d = {le(b, end64 + 32, 8), le(b, end64 + 48, 8), le(b, end64 + 40, 8)};
    }
    if (d.offset > b.size() || d.size > b.size() - d.offset)
      return invalid_argument(name + ": the ZIP central directory lies outside the file");
    return d;
  }
  return invalid_argument(name + " is not a .npz (ZIP) archive: no end of central directory");
}

// The ZIP64 extra field's values for the saturated 32-bit ones.
Status apply_zip64(std::string_view extra, Member& m, const std::string& what) {
  for (uint64_t at = 0; at + 4 <= extra.size();) {
    const uint64_t id = le(extra, at, 2), len = le(extra, at + 2, 2);
    if (at + 4 + len > extra.size()) break;
    if (id == kZip64Extra) {
      uint64_t p = at + 4;
      for (uint64_t* field : {&m.size, &m.compressed, &m.local_offset}) {
        if (*field != kSaturated) continue;
        if (p + 8 > at + 4 + len) return invalid_argument(what + ": short ZIP64 extra field");
        *field = le(extra, p, 8);
        p += 8;
      }
      return Status::Ok();
    }
    at += 4 + len;
  }
  if (m.size == kSaturated || m.compressed == kSaturated || m.local_offset == kSaturated)
    return invalid_argument(what + ": sizes saturated without a ZIP64 extra field");
  return Status::Ok();
}

Expected<std::string> inflate_member(std::string_view data, uint64_t size, const std::string& what) {
  // Deflate expands at most ~1032:1: a larger claim is a corrupt header, and
  // must not become an allocation.
  if (size > data.size() * 1100 + 1024)
    return data_loss(what + " claims to inflate " + std::to_string(data.size()) + " bytes to " +
                     std::to_string(size) + " (corrupt header)");
  std::string out(size, '\0');
  z_stream zs{};
  if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) return internal_error(what + ": zlib would not start");
  const auto* in_base = reinterpret_cast<const Bytef*>(data.data());
  auto* out_base = reinterpret_cast<Bytef*>(out.data());
  zs.next_in = const_cast<Bytef*>(in_base);
  zs.next_out = out_base;
  constexpr uint64_t kChunk = uint64_t{1} << 30;  // zlib counts in 32 bits
  int rc = Z_OK;
  for (;;) {
    const auto in_done = static_cast<uint64_t>(zs.next_in - in_base);
    const auto out_done = static_cast<uint64_t>(zs.next_out - out_base);
    if (zs.avail_in == 0) zs.avail_in = static_cast<uInt>(std::min(kChunk, data.size() - in_done));
    if (zs.avail_out == 0) zs.avail_out = static_cast<uInt>(std::min(kChunk, size - out_done));
    rc = inflate(&zs, Z_NO_FLUSH);
    if (rc != Z_OK) break;  // Z_STREAM_END, or an error (Z_BUF_ERROR: input or room ran out)
  }
  const auto out_done = static_cast<uint64_t>(zs.next_out - out_base);
  inflateEnd(&zs);
  if (rc != Z_STREAM_END || out_done != size)
    return data_loss(what + ": its deflated data is corrupt or does not inflate to " + std::to_string(size) +
                     " bytes");
  return out;
}

Expected<std::string> read_member(std::string_view b, const Member& m, const std::string& archive) {
  const std::string what = archive + ", member " + m.name;
  if (m.flags & 1u) return invalid_argument(what + " is encrypted");
  if (m.local_offset > b.size() || b.size() - m.local_offset < 30 || le(b, m.local_offset, 4) != kLocalHeader)
    return invalid_argument(what + ": no local header where the directory says");
  const uint64_t start = m.local_offset + 30 + le(b, m.local_offset + 26, 2) + le(b, m.local_offset + 28, 2);
  if (start > b.size() || m.compressed > b.size() - start)
    return data_loss(what + " runs past the end of the archive (truncated?)");
  const std::string_view data = b.substr(start, m.compressed);
  std::string bytes;
  if (m.method == 0) {
    if (m.compressed != m.size) return invalid_argument(what + ": stored with two different sizes");
    bytes = std::string(data);
  } else if (m.method == 8) {
    OUTCORE_ASSIGN_OR_RETURN(bytes, inflate_member(data, m.size, what));
  } else {
    return invalid_argument(what + " uses ZIP compression method " + std::to_string(m.method) +
                            "; numpy.savez (stored) and savez_compressed (deflate) are read");
  }
  uLong crc = crc32(0L, Z_NULL, 0);
  for (uint64_t at = 0; at < bytes.size();) {
    const uint64_t n = std::min<uint64_t>(bytes.size() - at, std::numeric_limits<uInt>::max());
    crc = crc32(crc, reinterpret_cast<const Bytef*>(bytes.data() + at), static_cast<uInt>(n));
    at += n;
  }
  if (crc != m.crc) return data_loss(what + ": CRC-32 mismatch (the archive is corrupt)");
  return bytes;
}

}  // namespace

Expected<std::map<std::string, std::string>> decode_npz(std::string_view b, const std::string& name) {
  OUTCORE_ASSIGN_OR_RETURN(const Directory dir, find_directory(b, name));
  std::map<std::string, std::string> members;
  uint64_t at = dir.offset;
  for (uint64_t e = 0; e < dir.entries; ++e) {
    if (at > b.size() || b.size() - at < 46 || le(b, at, 4) != kDirectoryEntry)
      return invalid_argument(name + ": ZIP central directory entry " + std::to_string(e) + " is broken");
    Member m;
    m.flags = static_cast<uint16_t>(le(b, at + 8, 2));
    m.method = static_cast<uint16_t>(le(b, at + 10, 2));
    m.crc = static_cast<uint32_t>(le(b, at + 16, 4));
    m.compressed = le(b, at + 20, 4);
    m.size = le(b, at + 24, 4);
    const uint64_t name_len = le(b, at + 28, 2), extra_len = le(b, at + 30, 2),
                   comment_len = le(b, at + 32, 2);
    m.local_offset = le(b, at + 42, 4);
    if (b.size() - at - 46 < name_len + extra_len + comment_len)
      return invalid_argument(name + ": ZIP central directory entry " + std::to_string(e) +
                              " runs past the file");
    m.name = std::string(b.substr(at + 46, name_len));
    OUTCORE_RETURN_IF_ERROR(
        apply_zip64(b.substr(at + 46 + name_len, extra_len), m, name + ", member " + m.name));
    at += 46 + name_len + extra_len + comment_len;
    std::string key = m.name;
    if (key.size() > 4 && key.compare(key.size() - 4, 4, ".npy") == 0) key.resize(key.size() - 4);
    OUTCORE_ASSIGN_OR_RETURN(std::string bytes, read_member(b, m, name));
    if (!members.emplace(key, std::move(bytes)).second)
      return invalid_argument(name + ": member " + m.name + " appears twice");
  }
  return members;
}

Expected<std::map<std::string, std::string>> read_npz(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(const std::string bytes, read_whole_file(path));
  return decode_npz(bytes, path);
}

}  // namespace outcore
