// OBJ reader: a strict streaming parser of our own, not tinyobjloader, because
// tinyobjloader silently turns a garbled number into 0 and its callback API
// carries no line numbers; a damaged file must be rejected with
// "path:line: what", never packed as wrong geometry.
//
// Accepted subset: `v x y z [w]` (w, and the r g b colours some exporters
// append, are checked to be numbers and ignored); `f` with corners `v`, `v/vt`,
// `v//vn` or `v/vt/vn`, 1-based or negative (relative: -1 = the last vertex
// defined so far) vertex indices, k>3 corners fan-triangulated into
// (v0,vi,vi+1). Every other statement (vt, vn, vp, o, g, s, usemtl, mtllib, l,
// p, unknown keywords), comments and blank lines are ignored. A '#' starting a
// token ends the statement (trailing comments).
//
// Faces may index any earlier vertex, so positions are needed at random: when
// they fit in the source's allowance (SourceOptions::vertex_memory_bytes) they
// are kept (12 bytes each) and faces stream as they are read; otherwise the
// first stream() resolves the faces out of core (vertex_spill.h) into a
// triangle file that every stream() then reads. Either way the file is read
// through a bounded buffer, in one pass, as a face may only use vertices
// defined above it.
#include "core/io/obj_reader.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string_view>
#include <system_error>

#include "core/geometry/coordinate_limits.h"
#include "core/io/text_line_reader.h"
#include "core/io/vertex_spill.h"

namespace outcore {

namespace {

bool is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

// Splits one statement into whitespace-separated tokens, stopping at '#'.
class StatementTokens {
 public:
  explicit StatementTokens(std::string_view line) : cursor_(line.data()), end_(line.data() + line.size()) {}

  bool next(std::string_view& token) {
    while (cursor_ < end_ && is_blank(*cursor_)) ++cursor_;
    if (cursor_ == end_ || *cursor_ == '#') return false;
    const char* start = cursor_;
    while (cursor_ < end_ && !is_blank(*cursor_)) ++cursor_;
    token = std::string_view(start, static_cast<std::size_t>(cursor_ - start));
    return true;
  }

 private:
  const char* cursor_;
  const char* end_;
};

// Parses an optionally negative integer at the start of [cursor, last),
// advancing cursor. False if there is none or it overflows int64.
bool parse_leading_integer(const char*& cursor, const char* last, std::int64_t& value) {
  auto [end, error] = std::from_chars(cursor, last, value);
  if (error != std::errc()) return false;
  cursor = end;
  return true;
}

// State of one pass over the file into a face resolver (vertex_spill.h); one per
// stream() call so that calls are independent and yield identical triangles.
template <class FaceResolver>
class ObjPass {
 public:
  ObjPass(const std::string& path, FaceResolver& faces) : path_(path), faces_(faces) {}

  Status run() {
    OUTCORE_RETURN_IF_ERROR(reader_.open(path_));
    std::string_view line;
    while (reader_.next_line(line)) {
      StatementTokens tokens(line);
      std::string_view keyword;
      if (!tokens.next(keyword)) continue;
      if (keyword == "v") {
        OUTCORE_RETURN_IF_ERROR(parse_vertex(tokens));
      } else if (keyword == "f") {
        OUTCORE_RETURN_IF_ERROR(parse_face(tokens));
      }
    }
    return reader_.status();
  }

 private:
  Status error(const std::string& what) const {
    return invalid_argument(path_ + ":" + std::to_string(reader_.line_number()) + ": " + what);
  }

  Status parse_vertex(StatementTokens& tokens) {
    static constexpr char kAxes[] = "xyz";
    Vec3f position;
    std::string_view token;
    for (int axis = 0; axis < 3; ++axis) {
      if (!tokens.next(token)) {
        return error("vertex has " + std::to_string(axis) + " coordinate" + (axis == 1 ? "" : "s") +
                     "; expected 3 (v x y z)");
      }
      float& value = position[axis];
      switch (parse_real(token, value)) {
        case NumberParse::kOk: break;
        case NumberParse::kGarbled: return error("expected a number, got '" + std::string(token) + "'");
        case NumberParse::kTooLarge:
          return error(std::string("vertex coordinate ") + kAxes[axis] + " = " + std::string(token) +
                       " is too large for float32");
      }
      if (!std::isfinite(value)) {
        return error(std::string("vertex coordinate ") + kAxes[axis] + " is not finite ('" +
                     std::string(token) + "')");
      }
      if (!within_vertex_range(value)) {
        return error(std::string("vertex coordinate ") + kAxes[axis] + " = " + std::string(token) +
                     " is beyond " + kLargestVertexComponentText +
                     ", the largest the float ray/triangle tests handle (docs/INPUTS.md)");
      }
    }
    // w (or colours) are not used, but a garbled one still means a damaged file.
    while (tokens.next(token)) {
      float ignored;
      if (parse_real(token, ignored) == NumberParse::kGarbled) {
        return error("expected a number, got '" + std::string(token) + "'");
      }
    }
    return faces_.add_vertex(position);
  }

  // Resolves one face corner to a 0-based vertex index.
  Status parse_corner(std::string_view token, uint64_t& index) const {
    const char* cursor = token.data();
    const char* last = cursor + token.size();
    std::int64_t vertex = 0;
    std::int64_t unused = 0;
    bool well_formed = parse_leading_integer(cursor, last, vertex);
    // Texture and normal indices are not used, but must be integers so that a
    // garbled corner is rejected rather than half read.
    if (well_formed && cursor != last) {
      well_formed = *cursor++ == '/';
      if (well_formed && cursor != last && *cursor != '/') {
        well_formed = parse_leading_integer(cursor, last, unused) && (cursor == last || *cursor == '/');
      } else if (well_formed) {
        well_formed = cursor != last;  // "v/" alone
      }
      if (well_formed && cursor != last) {
        ++cursor;  // the second '/'
        well_formed = parse_leading_integer(cursor, last, unused) && cursor == last;
      }
    }
    if (!well_formed) {
      return error("expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '" + std::string(token) + "'");
    }
    const auto defined = static_cast<std::int64_t>(faces_.vertex_count());
    if (vertex == 0) return error("vertex index 0 is invalid (OBJ indices start at 1)");
    if (vertex > defined || vertex < -defined) {
      return error("vertex index " + std::to_string(vertex) + " out of range (" + std::to_string(defined) +
                   " vertices defined so far)");
    }
    index = static_cast<uint64_t>(vertex > 0 ? vertex - 1 : defined + vertex);
    return Status::Ok();
  }

  // Fans the corners out as they are read: corner j >= 2 closes triangle
  // (c0, c(j-1), cj), so no per-face storage is needed.
  Status parse_face(StatementTokens& tokens) {
    uint64_t first = 0, previous = 0, corners = 0;
    std::string_view token;
    while (tokens.next(token)) {
      uint64_t index = 0;
      OUTCORE_RETURN_IF_ERROR(parse_corner(token, index));
      if (corners == 0) {
        first = index;
      } else if (corners >= 2) {
        OUTCORE_RETURN_IF_ERROR(faces_.add_triangle(first, previous, index));
      }
      previous = index;
      ++corners;
    }
    if (corners < 3) {
      return error("face has " + std::to_string(corners) + " corner" + (corners == 1 ? "" : "s") +
                   "; at least 3 are needed");
    }
    return Status::Ok();
  }

  const std::string& path_;
  TextLineReader reader_;
  FaceResolver& faces_;
};

// How many `v` statements the file has, counting no further than limit + 1
// (enough to know that they do not fit). Only decides the path to take, so
// it just looks at each line's first token.
Expected<uint64_t> count_vertex_statements(const std::string& path, uint64_t limit) {
  TextLineReader reader;
  OUTCORE_RETURN_IF_ERROR(reader.open(path));
  uint64_t count = 0;
  std::string_view line;
  while (count <= limit && reader.next_line(line)) {
    std::size_t i = 0;
    while (i < line.size() && is_blank(line[i])) ++i;
    count += i < line.size() && line[i] == 'v' && (i + 1 == line.size() || is_blank(line[i + 1]));
  }
  OUTCORE_RETURN_IF_ERROR(reader.status());
  return count;
}

class ObjSource final : public TriangleSource {
 public:
  ObjSource(std::string path, SourceOptions options) : path_(std::move(path)), options_(std::move(options)) {}

  const std::string& description() const override { return path_; }

  Status stream(TriangleSink& sink) override {
    OUTCORE_ASSIGN_OR_RETURN(const bool fits, vertices_fit_in_memory());
    return faces_.stream<ObjPass>(path_, options_, fits, vertices_to_reserve_, sink);
  }

 private:
  // Decided once per source. A vertex statement takes at least 8 bytes
  // ("v 0 0 0\n"), so a small file cannot exceed the allowance and is not
  // counted; a larger one is counted up to the allowance.
  Expected<bool> vertices_fit_in_memory() {
    if (fits_in_memory_ >= 0) return fits_in_memory_ == 1;
    const uint64_t allowance = options_.vertex_memory_bytes / sizeof(Vec3f);
    bool fits = true;
    if (options_.vertex_memory_bytes > 0) {
      std::error_code ec;
      const uint64_t most = std::filesystem::file_size(path_, ec) / 8;
      if (ec || most > allowance) {
        OUTCORE_ASSIGN_OR_RETURN(const uint64_t counted, count_vertex_statements(path_, allowance));
        fits = counted <= allowance;
        vertices_to_reserve_ = counted;
      } else {
        vertices_to_reserve_ = most;  // untouched capacity costs no memory
      }
    }
    fits_in_memory_ = fits ? 1 : 0;
    return fits;
  }

  std::string path_;
  SourceOptions options_;
  int fits_in_memory_ = -1;  // unknown until the first stream()
  uint64_t vertices_to_reserve_ = 0;
  ResolvedFaces faces_;
};

}  // namespace

Expected<std::unique_ptr<TriangleSource>> open_obj_file(const std::string& path,
                                                        const SourceOptions& options) {
  OUTCORE_RETURN_IF_ERROR(check_readable_file(path));
  return std::unique_ptr<TriangleSource>(std::make_unique<ObjSource>(path, options));
}

}  // namespace outcore
