#include "core/io/npy.h"

#include <cctype>
#include <charconv>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string_view>

#include "core/util/atomic_file.h"

namespace outcore {

const char* const kHitsNpyDescr =
    "[('t_hit', '<f4'), ('geometry_id', '<u4'), ('primitive_id', '<u4'), ('u', '<f4'), ('v', '<f4'), "
    "('ng', '<f4', (3,))]";

namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicBytes = 6;

std::string strip_spaces(std::string_view s) {
  std::string out;
  for (char c : s) {
    if (!std::isspace(static_cast<unsigned char>(c))) out += c;
  }
  return out;
}

// Finds the value text after 'key': in a Python dict literal.
Expected<std::string_view> dict_value(std::string_view dict, std::string_view key, const std::string& name) {
  const std::string quoted = "'" + std::string(key) + "'";
  auto pos = dict.find(quoted);
  if (pos == std::string_view::npos)
    return invalid_argument(name + ": .npy header has no '" + std::string(key) + "'");
  pos = dict.find(':', pos + quoted.size());
  if (pos == std::string_view::npos) return invalid_argument(name + ": malformed .npy header");
  ++pos;
  while (pos < dict.size() && dict[pos] == ' ') ++pos;
  if (pos >= dict.size()) return invalid_argument(name + ": malformed .npy header");
  const char open = dict[pos];
  if (open == '\'' || open == '"') {
    const auto end = dict.find(open, pos + 1);
    if (end == std::string_view::npos) return invalid_argument(name + ": malformed .npy header");
    return dict.substr(pos + 1, end - pos - 1);
  }
  if (open == '[' || open == '(') {
    int depth = 0;
    for (std::size_t i = pos; i < dict.size(); ++i) {
      if (dict[i] == '[' || dict[i] == '(') ++depth;
      if (dict[i] == ']' || dict[i] == ')') {
        if (--depth == 0) return dict.substr(pos, i - pos + 1);
      }
    }
    return invalid_argument(name + ": malformed .npy header");
  }
  auto end = dict.find_first_of(",}", pos);
  if (end == std::string_view::npos) end = dict.size();
  return dict.substr(pos, end - pos);
}

std::string shape_text(const std::vector<uint64_t>& shape) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  if (shape.size() == 1) s += ",";
  return s + ")";
}

std::string make_header(const std::string& descr, const std::vector<uint64_t>& shape) {
  std::string dict = "{'descr': " + (descr.front() == '[' ? descr : "'" + descr + "'") +
                     ", 'fortran_order': False, 'shape': " + shape_text(shape) + ", }";
  // Pad so the data starts on a 64-byte boundary, as numpy does.
  const std::size_t prefix = kMagicBytes + 2 + 2;
  std::size_t total = prefix + dict.size() + 1;
  const std::size_t padded = (total + 63) / 64 * 64;
  dict.append(padded - total, ' ');
  dict += '\n';
  std::string header(kMagic, kMagicBytes);
  header += '\x01';
  header += '\x00';
  const auto len = static_cast<uint16_t>(dict.size());
  header += static_cast<char>(len & 0xff);
  header += static_cast<char>(len >> 8);
  return header + dict;
}

// Under a temporary name, renamed into place: a failed write (disk full)
// leaves any earlier file whole and no truncated one behind.
Status write_file(const std::string& path, const std::string& header, const void* data, std::size_t bytes) {
  const std::string_view parts[] = {header, {static_cast<const char*>(data), bytes}};
  return write_file_atomically(path, parts);
}

// Checks shape, dtype and size; returns the data bytes.
Expected<std::string_view> array_data(std::string_view bytes, const std::string& name,
                                      const NpyHeader& header, uint64_t record_bytes) {
  uint64_t want = record_bytes;
  for (uint64_t d : header.shape) {
    if (d != 0 && want > std::numeric_limits<uint64_t>::max() / d) {
      return invalid_argument(name + " has shape " + shape_text(header.shape) + ", too large for any file");
    }
    want *= d;
  }
  const uint64_t have = bytes.size() - header.data_offset;
  if (have < want) {
    return data_loss(name + " is truncated: shape " + shape_text(header.shape) + " needs " +
                     std::to_string(want) + " bytes of data, the file has " + std::to_string(have));
  }
  if (have > want) {
    return invalid_argument(name + " has " + std::to_string(have - want) +
                            " bytes after the array data (shape " + shape_text(header.shape) + ")");
  }
  return bytes.substr(header.data_offset, want);
}

}  // namespace

Expected<std::string> read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return io_error_from_errno("cannot open " + path);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) return io_error_from_errno("cannot read " + path);
  return std::move(buffer).str();
}

Expected<NpyHeader> parse_npy_header(std::string_view bytes, const std::string& name) {
  if (bytes.size() < kMagicBytes || std::memcmp(bytes.data(), kMagic, kMagicBytes) != 0) {
    return invalid_argument(name + " is not a .npy file (bad magic)");
  }
  if (bytes.size() < kMagicBytes + 4) return data_loss(name + " is truncated inside its .npy header");
  const auto major = static_cast<uint8_t>(bytes[6]);
  uint64_t header_len = 0;
  std::size_t prefix = 0;
  if (major == 1) {
    header_len =
        static_cast<uint8_t>(bytes[8]) | (static_cast<uint64_t>(static_cast<uint8_t>(bytes[9])) << 8);
    prefix = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) return data_loss(name + " is truncated inside its .npy header");
    for (int i = 0; i < 4; ++i)
      header_len |= static_cast<uint64_t>(static_cast<uint8_t>(bytes[8 + i])) << (8 * i);
    prefix = 12;
  } else {
    return invalid_argument(name + ": unsupported .npy format version " + std::to_string(major));
  }
  if (bytes.size() < prefix + header_len) return data_loss(name + " is truncated inside its .npy header");
  const std::string_view dict = bytes.substr(prefix, header_len);
  NpyHeader header;
  header.data_offset = prefix + header_len;
  OUTCORE_ASSIGN_OR_RETURN(auto descr, dict_value(dict, "descr", name));
  header.descr = std::string(descr);
  OUTCORE_ASSIGN_OR_RETURN(auto fortran, dict_value(dict, "fortran_order", name));
  const std::string fortran_text = strip_spaces(fortran);
  if (fortran_text != "True" && fortran_text != "False")
    return invalid_argument(name + ": malformed fortran_order");
  header.fortran_order = fortran_text == "True";
  OUTCORE_ASSIGN_OR_RETURN(auto shape, dict_value(dict, "shape", name));
  const std::string shape_clean = strip_spaces(shape);
  if (shape_clean.size() < 2 || shape_clean.front() != '(' || shape_clean.back() != ')') {
    return invalid_argument(name + ": malformed shape " + std::string(shape));
  }
  std::string_view dims(shape_clean);
  dims = dims.substr(1, dims.size() - 2);
  while (!dims.empty()) {
    const auto comma = dims.find(',');
    const std::string_view item = dims.substr(0, comma);
    if (!item.empty()) {
      uint64_t value = 0;
      const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), value);
      if (ec != std::errc() || ptr != item.data() + item.size()) {
        return invalid_argument(name + ": malformed shape " + std::string(shape));
      }
      header.shape.push_back(value);
    }
    if (comma == std::string_view::npos) break;
    dims = dims.substr(comma + 1);
  }
  return header;
}

Expected<std::vector<Ray>> decode_rays_npy(std::string_view bytes, const std::string& name) {
  OUTCORE_ASSIGN_OR_RETURN(NpyHeader header, parse_npy_header(bytes, name));
  if (header.descr != "<f4") {
    return invalid_argument(name + " has dtype '" + header.descr +
                            "'; rays must be float32 ('<f4'), e.g. rays.astype(numpy.float32)");
  }
  if (header.fortran_order) return invalid_argument(name + " is in Fortran order; rays must be C order");
  if (header.shape.size() != 2 || (header.shape[1] != 6 && header.shape[1] != 8)) {
    return invalid_argument(name + " has shape " + shape_text(header.shape) +
                            "; rays must have shape (N, 6) (ox oy oz dx dy dz) or (N, 8) (... tnear tfar)");
  }
  const uint64_t count = header.shape[0];
  const uint64_t columns = header.shape[1];
  OUTCORE_ASSIGN_OR_RETURN(std::string_view data, array_data(bytes, name, header, sizeof(float)));
  std::vector<Ray> rays(count);
  for (uint64_t i = 0; i < count; ++i) {
    float row[8] = {0, 0, 0, 0, 0, 0, 0, std::numeric_limits<float>::infinity()};
    std::memcpy(row, data.data() + i * columns * sizeof(float), columns * sizeof(float));
    rays[i].origin = {row[0], row[1], row[2]};
    rays[i].direction = {row[3], row[4], row[5]};
    rays[i].tnear = row[6];
    rays[i].tfar = row[7];
  }
  return rays;
}

namespace {

template <typename T>
void widen_into(std::string_view data, std::vector<double>& out) {
  for (std::size_t i = 0; i < out.size(); ++i) {
    T value;
    std::memcpy(&value, data.data() + i * sizeof(T), sizeof(T));
    out[i] = static_cast<double>(value);
  }
}

}  // namespace

std::string npy_shape_text(const std::vector<uint64_t>& shape) {
  return shape_text(shape);
}

Expected<std::string_view> npy_array_data(std::string_view bytes, const std::string& name,
                                          const NpyHeader& header, uint64_t item_bytes) {
  return array_data(bytes, name, header, item_bytes);
}

Expected<NpyNumbers> decode_numeric_npy(std::string_view bytes, const std::string& name) {
  OUTCORE_ASSIGN_OR_RETURN(NpyHeader header, parse_npy_header(bytes, name));
  if (header.fortran_order) return invalid_argument(name + " is in Fortran order; C order is needed");
  struct Kind {
    const char* descr;
    uint64_t size;
    bool integral;
    void (*widen)(std::string_view, std::vector<double>&);
  };
  static constexpr Kind kKinds[] = {
      {"<f4", 4, false, widen_into<float>},   {"<f8", 8, false, widen_into<double>},
      {"|i1", 1, true, widen_into<int8_t>},   {"|u1", 1, true, widen_into<uint8_t>},
      {"|b1", 1, true, widen_into<uint8_t>},  {"<i2", 2, true, widen_into<int16_t>},
      {"<u2", 2, true, widen_into<uint16_t>}, {"<i4", 4, true, widen_into<int32_t>},
      {"<u4", 4, true, widen_into<uint32_t>}, {"<i8", 8, true, widen_into<int64_t>},
      {"<u8", 8, true, widen_into<uint64_t>},
  };
  for (const Kind& kind : kKinds) {
    if (header.descr != kind.descr) continue;
    OUTCORE_ASSIGN_OR_RETURN(std::string_view data, array_data(bytes, name, header, kind.size));
    NpyNumbers numbers;
    numbers.shape = header.shape;
    numbers.integral = kind.integral;
    numbers.values.resize(data.size() / kind.size);
    kind.widen(data, numbers.values);
    return numbers;
  }
  return invalid_argument(name + " has dtype '" + header.descr +
                          "'; a real or integer little-endian array is needed (e.g. float32, int64)");
}

Expected<std::vector<Ray>> read_rays_npy(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(std::string bytes, read_whole_file(path));
  return decode_rays_npy(bytes, path);
}

Status write_rays_npy(const std::string& path, std::span<const Ray> rays) {
  return write_file(path, make_header("<f4", {rays.size(), 8}), rays.data(), rays.size_bytes());
}

Status write_hits_npy(const std::string& path, std::span<const Hit> hits) {
  return write_file(path, make_header(kHitsNpyDescr, {hits.size()}), hits.data(), hits.size_bytes());
}

Expected<std::vector<Hit>> read_hits_npy(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(std::string bytes, read_whole_file(path));
  OUTCORE_ASSIGN_OR_RETURN(NpyHeader header, parse_npy_header(bytes, path));
  if (strip_spaces(header.descr) != strip_spaces(kHitsNpyDescr) || header.shape.size() != 1) {
    return invalid_argument(path + " is not a hits file (dtype " + header.descr + ", shape " +
                            shape_text(header.shape) + ")");
  }
  OUTCORE_ASSIGN_OR_RETURN(std::string_view data, array_data(bytes, path, header, sizeof(Hit)));
  std::vector<Hit> hits(header.shape[0]);
  if (!data.empty()) std::memcpy(hits.data(), data.data(), data.size());
  return hits;
}

Status write_bools_npy(const std::string& path, std::span<const uint8_t> flags) {
  return write_file(path, make_header("|b1", {flags.size()}), flags.data(), flags.size());
}

Status write_points_npy(const std::string& path, std::span<const Vec3f> points) {
  static_assert(sizeof(Vec3f) == 12);
  return write_file(path, make_header("<f4", {points.size(), 3}), points.data(), points.size_bytes());
}

Expected<std::vector<uint8_t>> read_bools_npy(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(std::string bytes, read_whole_file(path));
  OUTCORE_ASSIGN_OR_RETURN(NpyHeader header, parse_npy_header(bytes, path));
  if (header.descr != "|b1" || header.shape.size() != 1) {
    return invalid_argument(path + " is not a bool array (dtype " + header.descr + ", shape " +
                            shape_text(header.shape) + ")");
  }
  OUTCORE_ASSIGN_OR_RETURN(std::string_view data, array_data(bytes, path, header, 1));
  return std::vector<uint8_t>(data.begin(), data.end());
}

}  // namespace outcore
