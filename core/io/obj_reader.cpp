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
// Vertices are kept (12 bytes each: faces may index any earlier vertex); faces
// are streamed, and the file is read through a bounded buffer. A face may only
// use vertices defined above it, so the file is read in one pass.
#include "core/io/obj_reader.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/io/text_line_reader.h"

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

// State of one pass over the file; one per stream() call so that calls are
// independent and yield identical triangles.
class ObjPass {
 public:
  ObjPass(const std::string& path, TriangleSink& sink) : path_(path), batcher_(sink) {}

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
    OUTCORE_RETURN_IF_ERROR(reader_.status());
    return batcher_.finish();
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
    }
    // w (or colours) are not used, but a garbled one still means a damaged file.
    while (tokens.next(token)) {
      float ignored;
      if (parse_real(token, ignored) == NumberParse::kGarbled) {
        return error("expected a number, got '" + std::string(token) + "'");
      }
    }
    vertices_.push_back(position);
    return Status::Ok();
  }

  // Resolves one face corner to a 0-based index into vertices_.
  Status parse_corner(std::string_view token, std::size_t& index) const {
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
    const auto defined = static_cast<std::int64_t>(vertices_.size());
    if (vertex == 0) return error("vertex index 0 is invalid (OBJ indices start at 1)");
    if (vertex > defined || vertex < -defined) {
      return error("vertex index " + std::to_string(vertex) + " out of range (" + std::to_string(defined) +
                   " vertices defined so far)");
    }
    index = static_cast<std::size_t>(vertex > 0 ? vertex - 1 : defined + vertex);
    return Status::Ok();
  }

  // Fans the corners out as they are read: corner j >= 2 closes triangle
  // (c0, c(j-1), cj), so no per-face storage is needed.
  Status parse_face(StatementTokens& tokens) {
    std::size_t first = 0, previous = 0, corners = 0;
    std::string_view token;
    while (tokens.next(token)) {
      std::size_t index = 0;
      OUTCORE_RETURN_IF_ERROR(parse_corner(token, index));
      if (corners == 0) {
        first = index;
      } else if (corners >= 2) {
        OUTCORE_RETURN_IF_ERROR(
            batcher_.add(Triangle{vertices_[first], vertices_[previous], vertices_[index]}));
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
  std::vector<Vec3f> vertices_;
  TriangleBatcher batcher_;
};

class ObjSource final : public TriangleSource {
 public:
  explicit ObjSource(std::string path) : path_(std::move(path)) {}

  const std::string& description() const override { return path_; }

  Status stream(TriangleSink& sink) override {
    // On the heap: the batcher's buffer is too large for a small thread stack.
    auto pass = std::make_unique<ObjPass>(path_, sink);
    return pass->run();
  }

 private:
  std::string path_;
};

}  // namespace

Expected<std::unique_ptr<TriangleSource>> open_obj_file(const std::string& path) {
  OUTCORE_RETURN_IF_ERROR(check_readable_file(path));
  return std::unique_ptr<TriangleSource>(std::make_unique<ObjSource>(path));
}

}  // namespace outcore
