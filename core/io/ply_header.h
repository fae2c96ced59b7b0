// The PLY header: the scalar types, elements and properties a PLY file
// declares, and parse_header(), which reads them and checks that the
// elements the reader uses (vertex, face, tristrips) have what it needs.
// Internal to the PLY reader (ply_reader.cpp), which reads the body.
//
// Thread-safety: free functions and plain values.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/io/text_line_reader.h"
#include "core/util/status.h"

namespace outcore::ply {

enum class ScalarType : std::uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

// The type a header names ("uchar", "float32", ...); false if none.
bool find_scalar_type(std::string_view name, ScalarType& type);
// The type's name, for messages.
const char* scalar_type_name(ScalarType type);
bool is_integer(ScalarType type);

// Calls fn(T{}) with T the C++ type of a PLY scalar type.
template <class Fn>
auto with_scalar_type(ScalarType type, Fn&& fn) {
  switch (type) {
    case ScalarType::kInt8: return fn(std::int8_t{});
    case ScalarType::kUint8: return fn(std::uint8_t{});
    case ScalarType::kInt16: return fn(std::int16_t{});
    case ScalarType::kUint16: return fn(std::uint16_t{});
    case ScalarType::kInt32: return fn(std::int32_t{});
    case ScalarType::kUint32: return fn(std::uint32_t{});
    case ScalarType::kFloat32: return fn(float{});
    case ScalarType::kFloat64: break;
  }
  return fn(double{});
}

// Bytes of one value in a binary body.
std::size_t scalar_size(ScalarType type);

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

struct PlyProperty {
  std::string name;
  ScalarType type = ScalarType::kFloat32;  // for a list, the type of its items
  bool is_list = false;
  ScalarType count_type = ScalarType::kUint8;  // lists only
};

enum class ElementRole { kVertices, kFaces, kTriStrips, kIgnored };

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  ElementRole role = ElementRole::kIgnored;
  // Positions in properties of what the role uses (-1 if not there).
  int x = -1, y = -1, z = -1;
  int vertex_indices = -1;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
};

// Shortest text that reads back as value ("1e+300", "nan"), for messages.
std::string format_number(double value);

inline bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

// Splits a line into whitespace-separated tokens.
class LineTokens {
 public:
  LineTokens() = default;
  explicit LineTokens(std::string_view line) : cursor_(line.data()), end_(line.data() + line.size()) {}

  bool next(std::string_view& token) {
    while (cursor_ < end_ && is_blank(*cursor_)) ++cursor_;
    if (cursor_ == end_) return false;
    const char* start = cursor_;
    while (cursor_ < end_ && !is_blank(*cursor_)) ++cursor_;
    token = std::string_view(start, static_cast<std::size_t>(cursor_ - start));
    return true;
  }
  bool empty() {
    while (cursor_ < end_ && is_blank(*cursor_)) ++cursor_;
    return cursor_ == end_;
  }

 private:
  const char* cursor_ = nullptr;
  const char* end_ = nullptr;
};

std::vector<std::string_view> split_tokens(std::string_view line);

// Reads the header, leaving the reader at the first byte of the body.
Expected<PlyHeader> parse_header(TextLineReader& reader);

}  // namespace outcore::ply
