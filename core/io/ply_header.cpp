#include "core/io/ply_header.h"

#include <charconv>
#include <system_error>

namespace outcore::ply {

namespace {

struct ScalarTypeName {
  std::string_view name;
  ScalarType type;
};
constexpr ScalarTypeName kScalarTypeNames[] = {
    {"char", ScalarType::kInt8},       {"int8", ScalarType::kInt8},       {"uchar", ScalarType::kUint8},
    {"uint8", ScalarType::kUint8},     {"short", ScalarType::kInt16},     {"int16", ScalarType::kInt16},
    {"ushort", ScalarType::kUint16},   {"uint16", ScalarType::kUint16},   {"int", ScalarType::kInt32},
    {"int32", ScalarType::kInt32},     {"uint", ScalarType::kUint32},     {"uint32", ScalarType::kUint32},
    {"float", ScalarType::kFloat32},   {"float32", ScalarType::kFloat32}, {"double", ScalarType::kFloat64},
    {"float64", ScalarType::kFloat64},
};

// parse_header's state: the header so far and what the checks need.
class HeaderParser {
 public:
  explicit HeaderParser(TextLineReader& reader) : reader_(reader), path_(reader.path()) {}

  Expected<PlyHeader> parse();

 private:
  Status error_at(std::uint64_t line, const std::string& what) const {
    return invalid_argument(path_ + ":" + std::to_string(line) + ": " + what);
  }
  Status error(const std::string& what) const { return error_at(reader_.line_number(), what); }
  Status read_magic();
  // Reads header lines up to 'end_header'.
  Status read_declarations();
  Status read_declaration(const std::vector<std::string_view>& tokens, std::string_view line);
  Status read_format(const std::vector<std::string_view>& tokens);
  Status read_element(const std::vector<std::string_view>& tokens, std::string_view line);
  Status read_property(const std::vector<std::string_view>& tokens, std::string_view line);
  // Finds what each role needs, naming the element's line if it is missing.
  Status resolve_roles();
  Status resolve_vertex(PlyElement& element, std::uint64_t line) const;
  Status resolve_indices(PlyElement& element, std::uint64_t line) const;

  TextLineReader& reader_;
  const std::string& path_;
  PlyHeader header_;
  bool have_format_ = false;
  bool have_vertices_ = false;
  std::vector<std::uint64_t> element_lines_;
};

Expected<PlyHeader> HeaderParser::parse() {
  OUTCORE_RETURN_IF_ERROR(read_magic());
  OUTCORE_RETURN_IF_ERROR(read_declarations());
  if (!have_format_) return error("the PLY header has no 'format' line");
  OUTCORE_RETURN_IF_ERROR(resolve_roles());
  return std::move(header_);
}

Status HeaderParser::read_magic() {
  std::string_view line;
  if (!reader_.next_line(line)) {
    OUTCORE_RETURN_IF_ERROR(reader_.status());
    return invalid_argument(path_ + ": empty file; expected a PLY header");
  }
  if (split_tokens(line) != std::vector<std::string_view>{"ply"}) {
    return error("not a PLY file (the first line must be 'ply')");
  }
  return Status::Ok();
}

Status HeaderParser::read_declarations() {
  std::string_view line;
  for (;;) {
    if (!reader_.next_line(line)) {
      OUTCORE_RETURN_IF_ERROR(reader_.status());
      return invalid_argument(path_ + ": the PLY header has no 'end_header' line");
    }
    const std::vector<std::string_view> tokens = split_tokens(line);
    if (tokens.empty() || tokens[0] == "comment" || tokens[0] == "obj_info") continue;
    if (tokens[0] == "end_header") {
      if (tokens.size() != 1) return error("expected 'end_header' alone on its line");
      return Status::Ok();
    }
    OUTCORE_RETURN_IF_ERROR(read_declaration(tokens, line));
  }
}

Status HeaderParser::read_declaration(const std::vector<std::string_view>& tokens, std::string_view line) {
  const std::string_view keyword = tokens[0];
  if (keyword == "format") return read_format(tokens);
  if (keyword == "element") return read_element(tokens, line);
  if (keyword == "property") return read_property(tokens, line);
  return error("unknown PLY header keyword '" + std::string(keyword) + "'");
}

Status HeaderParser::read_format(const std::vector<std::string_view>& tokens) {
  if (have_format_) return error("second 'format' line");
  if (tokens.size() != 3) {
    return error("expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
  }
  if (tokens[1] == "ascii") {
    header_.format = PlyFormat::kAscii;
  } else if (tokens[1] == "binary_little_endian") {
    header_.format = PlyFormat::kBinaryLittleEndian;
  } else if (tokens[1] == "binary_big_endian") {
    header_.format = PlyFormat::kBinaryBigEndian;
  } else {
    return error("unsupported PLY format '" + std::string(tokens[1]) +
                 "' (expected ascii, binary_little_endian or binary_big_endian)");
  }
  if (tokens[2] != "1.0") {
    return error("unsupported PLY version '" + std::string(tokens[2]) + "' (expected 1.0)");
  }
  have_format_ = true;
  return Status::Ok();
}

Status HeaderParser::read_element(const std::vector<std::string_view>& tokens, std::string_view line) {
  if (!have_format_) return error("'element' before the 'format' line");
  PlyElement element;
  std::uint64_t count = 0;
  const auto parsed_count =
      tokens.size() == 3 ? std::from_chars(tokens[2].data(), tokens[2].data() + tokens[2].size(), count)
                         : std::from_chars_result{nullptr, std::errc::invalid_argument};
  if (parsed_count.ec != std::errc() || parsed_count.ptr != tokens[2].data() + tokens[2].size()) {
    return error("expected 'element NAME COUNT' with COUNT a non-negative integer, got '" +
                 std::string(line) + "'");
  }
  element.name = std::string(tokens[1]);
  element.count = count;
  if (element.name == "vertex") {
    if (have_vertices_) return error("second 'vertex' element");
    have_vertices_ = true;
    element.role = ElementRole::kVertices;
  } else if (element.name == "face" || element.name == "tristrips") {
    if (!have_vertices_) {
      return error("element '" + element.name +
                   "' comes before element 'vertex'; vertices must precede the faces that use them");
    }
    element.role = element.name == "face" ? ElementRole::kFaces : ElementRole::kTriStrips;
  }
  header_.elements.push_back(std::move(element));
  element_lines_.push_back(reader_.line_number());
  return Status::Ok();
}

Status HeaderParser::read_property(const std::vector<std::string_view>& tokens, std::string_view line) {
  if (header_.elements.empty()) return error("'property' before any 'element'");
  PlyProperty property;
  const bool is_list = tokens.size() >= 2 && tokens[1] == "list";
  if (is_list ? tokens.size() != 5 : tokens.size() != 3) {
    return error("expected 'property TYPE NAME' or 'property list COUNT_TYPE ITEM_TYPE NAME', got '" +
                 std::string(line) + "'");
  }
  property.is_list = is_list;
  const std::string_view type_name = is_list ? tokens[3] : tokens[1];
  if (!find_scalar_type(type_name, property.type)) {
    return error("unknown property type '" + std::string(type_name) + "'");
  }
  if (is_list) {
    if (!find_scalar_type(tokens[2], property.count_type)) {
      return error("unknown property type '" + std::string(tokens[2]) + "'");
    }
    if (!is_integer(property.count_type)) {
      return error("list count type must be an integer type, got '" + std::string(tokens[2]) + "'");
    }
  }
  property.name = std::string(tokens.back());
  header_.elements.back().properties.push_back(std::move(property));
  return Status::Ok();
}

Status HeaderParser::resolve_roles() {
  for (std::size_t e = 0; e < header_.elements.size(); ++e) {
    PlyElement& element = header_.elements[e];
    if (element.role == ElementRole::kVertices) {
      OUTCORE_RETURN_IF_ERROR(resolve_vertex(element, element_lines_[e]));
    } else if (element.role == ElementRole::kFaces || element.role == ElementRole::kTriStrips) {
      OUTCORE_RETURN_IF_ERROR(resolve_indices(element, element_lines_[e]));
    }
  }
  return Status::Ok();
}

int find_property(const PlyElement& element, std::string_view name) {
  for (std::size_t p = 0; p < element.properties.size(); ++p) {
    if (element.properties[p].name == name) return static_cast<int>(p);
  }
  return -1;
}

Status HeaderParser::resolve_vertex(PlyElement& element, std::uint64_t line) const {
  int* positions[] = {&element.x, &element.y, &element.z};
  const char* names[] = {"x", "y", "z"};
  for (int axis = 0; axis < 3; ++axis) {
    *positions[axis] = find_property(element, names[axis]);
    if (*positions[axis] < 0) {
      return error_at(line, std::string("element 'vertex' has no property '") + names[axis] + "'");
    }
    if (element.properties[static_cast<std::size_t>(*positions[axis])].is_list) {
      return error_at(line, std::string("property '") + names[axis] +
                                "' of element 'vertex' is a list; expected a number");
    }
  }
  return Status::Ok();
}

Status HeaderParser::resolve_indices(PlyElement& element, std::uint64_t line) const {
  element.vertex_indices = find_property(element, "vertex_indices");
  if (element.vertex_indices < 0 && element.role == ElementRole::kFaces) {
    element.vertex_indices = find_property(element, "vertex_index");
  }
  if (element.vertex_indices < 0) {
    return error_at(line, "element '" + element.name + "' has no list property 'vertex_indices'" +
                              (element.role == ElementRole::kFaces ? " (or 'vertex_index')" : ""));
  }
  const PlyProperty& indices = element.properties[static_cast<std::size_t>(element.vertex_indices)];
  if (!indices.is_list || !is_integer(indices.type)) {
    return error_at(
        line, "property '" + indices.name + "' of element '" + element.name + "' must be a list of integers");
  }
  return Status::Ok();
}

}  // namespace

bool find_scalar_type(std::string_view name, ScalarType& type) {
  for (const ScalarTypeName& entry : kScalarTypeNames) {
    if (entry.name == name) {
      type = entry.type;
      return true;
    }
  }
  return false;
}

const char* scalar_type_name(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8: return "char";
    case ScalarType::kUint8: return "uchar";
    case ScalarType::kInt16: return "short";
    case ScalarType::kUint16: return "ushort";
    case ScalarType::kInt32: return "int";
    case ScalarType::kUint32: return "uint";
    case ScalarType::kFloat32: return "float";
    case ScalarType::kFloat64: return "double";
  }
  return "?";
}

bool is_integer(ScalarType type) {
  return type != ScalarType::kFloat32 && type != ScalarType::kFloat64;
}

std::size_t scalar_size(ScalarType type) {
  return with_scalar_type(type, [](auto zero) { return sizeof(zero); });
}

std::string format_number(double value) {
  char digits[64];
  const auto written = std::to_chars(digits, digits + sizeof(digits), value);
  return std::string(digits, written.ptr);
}

std::vector<std::string_view> split_tokens(std::string_view line) {
  std::vector<std::string_view> tokens;
  LineTokens cursor(line);
  std::string_view token;
  while (cursor.next(token)) tokens.push_back(token);
  return tokens;
}

Expected<PlyHeader> parse_header(TextLineReader& reader) {
  return HeaderParser(reader).parse();
}
}  // namespace outcore::ply
