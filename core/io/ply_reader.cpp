// PLY reader: header, then the elements in file order. The `vertex` element's
// x, y, z (any numeric type, converted to float) are kept, 12 bytes a vertex,
// when the header's vertex count fits the source's allowance
// (SourceOptions::vertex_memory_bytes); otherwise the first stream() resolves
// the faces out of core (vertex_spill.h) into a triangle file that every
// stream() then reads. `face` (list vertex_indices or vertex_index) and `tristrips` (list
// vertex_indices, -1 restarts a strip) are streamed as triangles; every other
// property and element is read past (list properties too, which is why binary
// files need the full header). Faces may only use vertices already read, so
// the `vertex` element must come first; the file is read in one pass through
// a bounded buffer.
//
// Strip expansion, per strip s (the list split at -1), for i = 0..len-3:
// i even -> (s[i], s[i+1], s[i+2]), i odd -> (s[i+1], s[i], s[i+2]), so that all
// triangles share the first one's winding. Degenerate strip triangles (repeated
// indices, used to join strips) are emitted too: they keep primitive ids equal
// to positions in the expanded strip.
//
// ASCII bodies hold one element item per line; this is what every writer
// produces, and it lets an error name the line of the offending item.
#include "core/io/ply_reader.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include "core/geometry/coordinate_limits.h"
#include "core/io/ply_header.h"
#include "core/io/text_line_reader.h"
#include "core/io/vertex_spill.h"

namespace outcore {

namespace {

using namespace ply;

enum class ReadResult { kOk, kEndOfFile, kMalformed };

// Reads values of a binary body in the file's byte order.
class BinaryBody {
 public:
  BinaryBody(TextLineReader& reader, bool big_endian)
      : reader_(reader), swap_(big_endian != (std::endian::native == std::endian::big)) {}

  std::string location() const { return reader_.path(); }
  const std::string& problem() const { return problem_; }

  ReadResult begin_item() { return ReadResult::kOk; }
  ReadResult end_item() { return ReadResult::kOk; }

  ReadResult read_number(ScalarType type, double& value) {
    return with_scalar_type(type, [&](auto zero) {
      decltype(zero) raw;
      if (!read_raw(raw)) return ReadResult::kEndOfFile;
      value = static_cast<double>(raw);
      return ReadResult::kOk;
    });
  }

  // type is an integer type (the header checked).
  ReadResult read_integer(ScalarType type, std::int64_t& value) {
    return with_scalar_type(type, [&](auto zero) {
      using T = decltype(zero);
      if constexpr (std::is_floating_point_v<T>) {
        problem_ = "internal: integer expected of a non-integer type";  // the header check prevents this
        return ReadResult::kMalformed;
      } else {
        T raw;
        if (!read_raw(raw)) return ReadResult::kEndOfFile;
        value = static_cast<std::int64_t>(raw);
        return ReadResult::kOk;
      }
    });
  }

  ReadResult skip(const PlyProperty& property) {
    std::uint64_t items = 1;
    if (property.is_list) {
      std::int64_t count = 0;
      const ReadResult result = read_integer(property.count_type, count);
      if (result != ReadResult::kOk) return result;
      if (count < 0) {
        problem_ = "list '" + property.name + "' has a negative length " + std::to_string(count);
        return ReadResult::kMalformed;
      }
      items = static_cast<std::uint64_t>(count);
    }
    return reader_.skip_bytes(items * scalar_size(property.type)) ? ReadResult::kOk : ReadResult::kEndOfFile;
  }

 private:
  template <class T>
  bool read_raw(T& value) {
    unsigned char bytes[sizeof(T)];
    if (!reader_.read_bytes(bytes, sizeof(T))) return false;
    if (swap_) std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(&value, bytes, sizeof(T));
    return true;
  }

  TextLineReader& reader_;
  bool swap_;
  std::string problem_;
};

// Reads values of an ascii body: one element item per line.
class AsciiBody {
 public:
  explicit AsciiBody(TextLineReader& reader) : reader_(reader) {}

  std::string location() const { return reader_.path() + ":" + std::to_string(reader_.line_number()); }
  const std::string& problem() const { return problem_; }

  ReadResult begin_item() {
    std::string_view line;
    do {
      if (!reader_.next_line(line)) return ReadResult::kEndOfFile;
      tokens_ = LineTokens(line);
    } while (tokens_.empty());
    return ReadResult::kOk;
  }

  ReadResult end_item() {
    std::string_view extra;
    if (!tokens_.next(extra)) return ReadResult::kOk;
    problem_ = "unexpected extra value '" + std::string(extra) + "' (more values than the header declares)";
    return ReadResult::kMalformed;
  }

  ReadResult read_number(ScalarType type, double& value) {
    std::string_view token;
    if (!next_token(token)) return ReadResult::kMalformed;
    if (is_integer(type)) {
      std::int64_t integer = 0;
      const ReadResult result = parse_integer(type, token, integer);
      value = static_cast<double>(integer);
      return result;
    }
    NumberParse parsed = NumberParse::kOk;
    if (type == ScalarType::kFloat32) {
      // Parsed as float directly: rounding through double could differ by an ulp.
      float narrow = 0;
      parsed = parse_real(token, narrow);
      value = narrow;
    } else {
      parsed = parse_real(token, value);
    }
    switch (parsed) {
      case NumberParse::kOk: return ReadResult::kOk;
      case NumberParse::kGarbled:
        problem_ = "expected a number (" + std::string(scalar_type_name(type)) + "), got '" +
                   std::string(token) + "'";
        return ReadResult::kMalformed;
      case NumberParse::kTooLarge: break;
    }
    problem_ = "value " + std::string(token) + " is too large for type " + scalar_type_name(type);
    return ReadResult::kMalformed;
  }

  ReadResult read_integer(ScalarType type, std::int64_t& value) {
    std::string_view token;
    if (!next_token(token)) return ReadResult::kMalformed;
    return parse_integer(type, token, value);
  }

  ReadResult skip(const PlyProperty& property) {
    std::uint64_t items = 1;
    if (property.is_list) {
      std::int64_t count = 0;
      const ReadResult result = read_integer(property.count_type, count);
      if (result != ReadResult::kOk) return result;
      if (count < 0) {
        problem_ = "list '" + property.name + "' has a negative length " + std::to_string(count);
        return ReadResult::kMalformed;
      }
      items = static_cast<std::uint64_t>(count);
    }
    // Skipped values are still checked: a garbled one means a damaged file.
    for (std::uint64_t i = 0; i < items; ++i) {
      double ignored = 0;
      const ReadResult result = read_number(property.type, ignored);
      if (result != ReadResult::kOk) return result;
    }
    return ReadResult::kOk;
  }

  // After the last element: only blank lines may follow.
  ReadResult check_no_more_items() {
    if (begin_item() == ReadResult::kEndOfFile) return ReadResult::kOk;
    problem_ = "unexpected data after the last element (the header declares fewer items)";
    return ReadResult::kMalformed;
  }

 private:
  bool next_token(std::string_view& token) {
    if (tokens_.next(token)) return true;
    problem_ = "line ends early (fewer values than the header declares)";
    return false;
  }

  ReadResult parse_integer(ScalarType type, std::string_view token, std::int64_t& value) {
    const char* last = token.data() + token.size();
    auto [end, error] = std::from_chars(token.data(), last, value);
    if (error != std::errc() || end != last) {
      problem_ = "expected an integer (" + std::string(scalar_type_name(type)) + "), got '" +
                 std::string(token) + "'";
      return ReadResult::kMalformed;
    }
    const bool fits = with_scalar_type(type, [&](auto zero) {
      using T = decltype(zero);
      if constexpr (std::is_floating_point_v<T>) {
        return true;
      } else {
        return value >= static_cast<std::int64_t>(std::numeric_limits<T>::min()) &&
               value <= static_cast<std::int64_t>(std::numeric_limits<T>::max());
      }
    });
    if (!fits) {
      problem_ = "value " + std::string(token) + " does not fit in type " + scalar_type_name(type);
      return ReadResult::kMalformed;
    }
    return ReadResult::kOk;
  }

  TextLineReader& reader_;
  LineTokens tokens_;
  std::string problem_;
};

// State of one pass over the file into a face resolver (vertex_spill.h); one per
// stream() call so that calls are independent and yield identical triangles.
template <class FaceResolver>
class PlyPass {
 public:
  PlyPass(const std::string& path, FaceResolver& faces) : path_(path), faces_(faces) {}

  Status run() {
    OUTCORE_RETURN_IF_ERROR(reader_.open(path_));
    OUTCORE_ASSIGN_OR_RETURN(header_, parse_header(reader_));
    if (header_.format == PlyFormat::kAscii) {
      AsciiBody body(reader_);
      OUTCORE_RETURN_IF_ERROR(read_elements(body));
      if (body.check_no_more_items() != ReadResult::kOk) {
        OUTCORE_RETURN_IF_ERROR(reader_.status());
        return invalid_argument(body.location() + ": " + body.problem());
      }
    } else {
      BinaryBody body(reader_, header_.format == PlyFormat::kBinaryBigEndian);
      OUTCORE_RETURN_IF_ERROR(read_elements(body));
    }
    return reader_.status();
  }

 private:
  template <class Body>
  Status read_elements(Body& body) {
    for (const PlyElement& element : header_.elements) {
      switch (element.role) {
        case ElementRole::kVertices: OUTCORE_RETURN_IF_ERROR(read_vertices(body, element)); break;
        case ElementRole::kFaces:
        case ElementRole::kTriStrips: OUTCORE_RETURN_IF_ERROR(read_polygons(body, element)); break;
        case ElementRole::kIgnored: OUTCORE_RETURN_IF_ERROR(skip_element(body, element)); break;
      }
    }
    return Status::Ok();
  }

  // Turns a failed read into its Status: an I/O error, a truncated file, or
  // the body's description of a malformed value.
  template <class Body>
  Status read_failure(const Body& body, ReadResult result, const PlyElement& element,
                      std::uint64_t item) const {
    if (!reader_.status().ok()) return reader_.status();
    if (result == ReadResult::kEndOfFile) {
      return invalid_argument(path_ + ": unexpected end of file in element '" + element.name + "' at index " +
                              std::to_string(item) + " (the header declares " +
                              std::to_string(element.count) + ")");
    }
    return item_error(body, element, item, body.problem());
  }

  template <class Body>
  Status item_error(const Body& body, const PlyElement& element, std::uint64_t item,
                    const std::string& what) const {
    return invalid_argument(body.location() + ": " + element.name + " " + std::to_string(item) + ": " + what);
  }

  template <class Body>
  Status skip_element(Body& body, const PlyElement& element) {
    for (std::uint64_t item = 0; item < element.count; ++item) {
      ReadResult result = body.begin_item();
      for (std::size_t p = 0; result == ReadResult::kOk && p < element.properties.size(); ++p) {
        result = body.skip(element.properties[p]);
      }
      if (result == ReadResult::kOk) result = body.end_item();
      if (result != ReadResult::kOk) return read_failure(body, result, element, item);
    }
    return Status::Ok();
  }

  template <class Body>
  Status read_vertices(Body& body, const PlyElement& element) {
    static constexpr char kAxes[] = "xyz";
    // Capped: the count is the file's claim, not yet checked against its size.
    faces_.reserve_vertices(std::min<std::uint64_t>(element.count, std::uint64_t{1} << 24));
    for (std::uint64_t item = 0; item < element.count; ++item) {
      double xyz[3] = {0, 0, 0};
      ReadResult result = body.begin_item();
      for (std::size_t p = 0; result == ReadResult::kOk && p < element.properties.size(); ++p) {
        const int position = static_cast<int>(p);
        const int axis = position == element.x   ? 0
                         : position == element.y ? 1
                         : position == element.z ? 2
                                                 : -1;
        result = axis >= 0 ? body.read_number(element.properties[p].type, xyz[axis])
                           : body.skip(element.properties[p]);
      }
      if (result == ReadResult::kOk) result = body.end_item();
      if (result != ReadResult::kOk) return read_failure(body, result, element, item);
      Vec3f position;
      for (int axis = 0; axis < 3; ++axis) {
        position[axis] = static_cast<float>(xyz[axis]);
        if (!std::isfinite(position[axis])) {
          return item_error(body, element, item,
                            std::string("coordinate ") + kAxes[axis] + " is not finite in float32 (" +
                                format_number(xyz[axis]) + ")");
        }
        if (!within_vertex_range(position[axis])) {
          return item_error(body, element, item,
                            std::string("coordinate ") + kAxes[axis] + " = " + format_number(xyz[axis]) +
                                " is beyond " + kLargestVertexComponentText +
                                ", the largest the float ray/triangle tests handle (docs/INPUTS.md)");
        }
      }
      OUTCORE_RETURN_IF_ERROR(faces_.add_vertex(position));
    }
    return Status::Ok();
  }

  // Faces are fanned (c0, c(j-1), cj) as corner j >= 2 is read; strips emit
  // one triangle per index from the third of each strip on. Either way no
  // per-item storage is needed, so a strip may be arbitrarily long.
  template <class Body>
  Status read_polygons(Body& body, const PlyElement& element) {
    const bool strips = element.role == ElementRole::kTriStrips;
    const auto vertex_count = static_cast<std::int64_t>(faces_.vertex_count());
    for (std::uint64_t item = 0; item < element.count; ++item) {
      ReadResult result = body.begin_item();
      for (std::size_t p = 0; result == ReadResult::kOk && p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        if (static_cast<int>(p) != element.vertex_indices) {
          result = body.skip(property);
          continue;
        }
        std::int64_t count = 0;
        result = body.read_integer(property.count_type, count);
        if (result != ReadResult::kOk) break;
        if (!strips && count < 3) {
          return item_error(body, element, item,
                            "has " + std::to_string(count) + " corner" + (count == 1 ? "" : "s") +
                                "; at least 3 are needed");
        }
        if (count < 0) {
          return item_error(body, element, item, "list has a negative length " + std::to_string(count));
        }
        // Corners of the current face or strip: the first (faces) or the two
        // before (strips), and how many have been read.
        std::uint64_t a = 0, b = 0;
        std::int64_t in_strip = 0;
        for (std::int64_t j = 0; j < count; ++j) {
          std::int64_t index = 0;
          result = body.read_integer(property.type, index);
          if (result != ReadResult::kOk) break;
          if (strips && index == -1) {
            in_strip = 0;
            continue;
          }
          if (index < 0 || index >= vertex_count) {
            return item_error(body, element, item,
                              "vertex index " + std::to_string(index) + " out of range (" +
                                  std::to_string(vertex_count) + " vertices)" +
                                  (strips ? " at list position " + std::to_string(j) : std::string()));
          }
          const auto c = static_cast<std::uint64_t>(index);
          if (in_strip >= 2) {
            const bool flip = strips && (in_strip - 2) % 2 == 1;
            OUTCORE_RETURN_IF_ERROR(flip ? faces_.add_triangle(b, a, c) : faces_.add_triangle(a, b, c));
          }
          if (strips) {
            a = b;
            b = c;
          } else if (in_strip == 0) {
            a = c;
          } else {
            b = c;
          }
          ++in_strip;
        }
      }
      if (result == ReadResult::kOk) result = body.end_item();
      if (result != ReadResult::kOk) return read_failure(body, result, element, item);
    }
    return Status::Ok();
  }

  const std::string& path_;
  TextLineReader reader_;
  PlyHeader header_;
  FaceResolver& faces_;
};

class PlySource final : public TriangleSource {
 public:
  PlySource(std::string path, const SourceOptions& options, std::uint64_t vertex_count)
      : path_(std::move(path)),
        options_(options),
        spill_(options.vertex_memory_bytes > 0 &&
               vertex_count > options.vertex_memory_bytes / sizeof(Vec3f)) {}

  const std::string& description() const override { return path_; }

  Status stream(TriangleSink& sink) override {
    // read_vertices reserves from the header's count.
    return faces_.stream<PlyPass>(path_, options_, !spill_, /*vertices_to_reserve=*/0, sink);
  }

 private:
  std::string path_;
  SourceOptions options_;
  bool spill_;  // the header's vertices exceed the allowance
  ResolvedFaces faces_;
};

}  // namespace

Expected<std::unique_ptr<TriangleSource>> open_ply_file(const std::string& path,
                                                        const SourceOptions& options) {
  // The header is checked now so that a wrong file fails before any work; each
  // stream() reads it again, as the body cannot be read without it.
  TextLineReader reader;
  OUTCORE_RETURN_IF_ERROR(reader.open(path));
  OUTCORE_ASSIGN_OR_RETURN(PlyHeader header, parse_header(reader));
  std::uint64_t vertex_count = 0;
  for (const PlyElement& element : header.elements) {
    if (element.role == ElementRole::kVertices) vertex_count = element.count;
  }
  return std::unique_ptr<TriangleSource>(std::make_unique<PlySource>(path, options, vertex_count));
}

}  // namespace outcore
