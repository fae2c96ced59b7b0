#include "core/io/npz_mesh_reader.h"

#include <sys/stat.h>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <span>
#include <vector>

#include "core/geometry/coordinate_limits.h"
#include "core/io/npy.h"
#include "core/io/npz_reader.h"
#include "core/io/vertex_spill.h"
#include "core/util/file_type.h"

namespace outcore {
namespace {

using Members = std::map<std::string, std::string>;
using IndexTriple = std::array<uint32_t, 3>;

struct Dtype {
  const char* descr;
  uint64_t bytes;
  bool is_float;
  bool is_signed;
};

constexpr Dtype kVertexDtypes[] = {{"<f4", 4, true, true}, {"<f8", 8, true, true}};
constexpr Dtype kIndexDtypes[] = {
    {"<i4", 4, false, true}, {"<i8", 8, false, true}, {"<u4", 4, false, false}, {"<u8", 8, false, false}};

// One (N, 3) member, checked: its data and how its elements are laid out.
struct Array3 {
  std::string what;  // "scene.npz, member vertices", the prefix of every message about it
  Dtype dtype{};
  bool fortran_order = false;
  uint64_t rows = 0;
  std::string_view data;

  template <class T>
  T load(uint64_t row, int column) const {
    // Fortran order is what numpy.save writes for a transposed (3, N) array.
    const uint64_t index = fortran_order ? uint64_t(column) * rows + row : row * 3 + uint64_t(column);
    T value;
    std::memcpy(&value, data.data() + index * sizeof(T), sizeof(T));
    return value;
  }
  std::string row_error_prefix(uint64_t row) const { return what + ": row " + std::to_string(row) + ": "; }
};

std::string member_list(const Members& members) {
  std::string names;
  for (const auto& [name, bytes] : members) names += (names.empty() ? "" : ", ") + name;
  return names.empty() ? "none" : names;
}

// The member `key` as an (N, 3) array of one of `dtypes`; `wanted` describes
// them for messages ("float32 or float64").
Expected<Array3> find_array(const Members& members, const std::string& name, const std::string& key,
                            std::span<const Dtype> dtypes, const std::string& wanted) {
  const auto it = members.find(key);
  if (it == members.end()) {
    return invalid_argument(name + ": no member '" + key +
                            "' (an .npz mesh needs 'vertices' (V, 3) float32/float64 and 'triangles' (T, 3) "
                            "int32/int64/uint32/uint64; the archive has: " +
                            member_list(members) + ")");
  }
  Array3 array;
  array.what = name + ", member " + key;
  OUTCORE_ASSIGN_OR_RETURN(const NpyHeader header, parse_npy_header(it->second, array.what));
  const Dtype* found = nullptr;
  for (const Dtype& dtype : dtypes) {
    if (header.descr == dtype.descr) found = &dtype;
  }
  if (found == nullptr) {
    return invalid_argument(array.what + " has dtype '" + header.descr + "'; " + key + " must be " + wanted);
  }
  if (header.shape.size() != 2 || header.shape[1] != 3) {
    return invalid_argument(array.what + " has shape " + npy_shape_text(header.shape) + "; " + key +
                            " must have shape (N, 3)");
  }
  array.dtype = *found;
  array.fortran_order = header.fortran_order;
  array.rows = header.shape[0];
  OUTCORE_ASSIGN_OR_RETURN(array.data, npy_array_data(it->second, array.what, header, found->bytes));
  return array;
}

// The shortest text that reads back as the stored value (of its own width).
std::string number_text(const Array3& a, uint64_t row, int column) {
  char text[64];
  const auto written = a.dtype.bytes == 4
                           ? std::to_chars(text, text + sizeof text, a.load<float>(row, column))
                           : std::to_chars(text, text + sizeof text, a.load<double>(row, column));
  return std::string(text, written.ptr);
}

Status convert_vertices(const Array3& a, std::vector<Vec3f>& out) {
  static constexpr char kAxes[] = "xyz";
  out.resize(a.rows);
  for (uint64_t row = 0; row < a.rows; ++row) {
    for (int axis = 0; axis < 3; ++axis) {
      // The same rounding and checks as the PLY reader's, which also reads
      // doubles into float32.
      const float value =
          a.dtype.bytes == 4 ? a.load<float>(row, axis) : static_cast<float>(a.load<double>(row, axis));
      if (!std::isfinite(value)) {
        return invalid_argument(a.row_error_prefix(row) + "coordinate " + kAxes[axis] +
                                " is not finite in float32 (" + number_text(a, row, axis) + ")");
      }
      if (!within_vertex_range(value)) {
        return invalid_argument(a.row_error_prefix(row) + "coordinate " + kAxes[axis] + " = " +
                                number_text(a, row, axis) + " is beyond " + kLargestVertexComponentText +
                                ", the largest the float ray/triangle tests handle (docs/INPUTS.md)");
      }
      out[row][axis] = value;
    }
  }
  return Status::Ok();
}

Status convert_triangles(const Array3& a, uint64_t vertex_count, std::vector<IndexTriple>& out) {
  out.resize(a.rows);
  for (uint64_t row = 0; row < a.rows; ++row) {
    for (int corner = 0; corner < 3; ++corner) {
      int64_t signed_index = 0;
      uint64_t index = 0;
      if (a.dtype.is_signed) {
        signed_index = a.dtype.bytes == 4 ? a.load<int32_t>(row, corner) : a.load<int64_t>(row, corner);
        index = static_cast<uint64_t>(signed_index);
      } else {
        index = a.dtype.bytes == 4 ? a.load<uint32_t>(row, corner) : a.load<uint64_t>(row, corner);
      }
      if (signed_index < 0 || index >= vertex_count) {
        const std::string text = a.dtype.is_signed ? std::to_string(signed_index) : std::to_string(index);
        return invalid_argument(a.row_error_prefix(row) + "vertex index " + text + " out of range (" +
                                std::to_string(vertex_count) + " vertices)");
      }
      out[row][corner] = static_cast<uint32_t>(index);
    }
  }
  return Status::Ok();
}

class NpzMeshSource final : public TriangleSource {
 public:
  NpzMeshSource(std::string name, std::vector<Vec3f> vertices, std::vector<IndexTriple> triangles)
      : name_(std::move(name)), vertices_(std::move(vertices)), triangles_(std::move(triangles)) {}

  const std::string& description() const override { return name_; }

  Status stream(TriangleSink& sink) override {
    // On the heap: the batcher's buffer is too large for a small thread stack.
    auto batcher = std::make_unique<TriangleBatcher>(sink);
    for (const IndexTriple& t : triangles_) {
      OUTCORE_RETURN_IF_ERROR(batcher->add(Triangle{vertices_[t[0]], vertices_[t[1]], vertices_[t[2]]}));
    }
    return batcher->finish();
  }
  bool cheap_to_restream() const override { return true; }
  uint64_t held_memory_bytes() const override {
    return vertices_.capacity() * sizeof(Vec3f) + triangles_.capacity() * sizeof(IndexTriple);
  }

 private:
  std::string name_;
  std::vector<Vec3f> vertices_;
  std::vector<IndexTriple> triangles_;
};

std::string mib_text(uint64_t bytes) {
  return std::to_string((bytes + (1 << 20) - 1) >> 20) + " MiB";
}

Expected<std::unique_ptr<TriangleSource>> mesh_from_members(const Members& members, const std::string& name,
                                                            const HeldMemoryLimit& held) {
  OUTCORE_ASSIGN_OR_RETURN(const Array3 vertices,
                           find_array(members, name, "vertices", kVertexDtypes, "float32 or float64"));
  OUTCORE_ASSIGN_OR_RETURN(const Array3 triangles,
                           find_array(members, name, "triangles", kIndexDtypes,
                                      "int32, int64, uint32 or uint64 (vertex indices)"));
  // Checked before anything is allocated for the mesh.
  if (triangles.rows >= kMaxTrianglesPerInput) {
    return invalid_argument(triangles.what + " has " + std::to_string(triangles.rows) +
                            " rows; primitive ids are 32-bit, so an input may hold at most 4294967294");
  }
  if (vertices.rows > 0xffffffffull) {
    return invalid_argument(vertices.what + " has " + std::to_string(vertices.rows) +
                            " rows; at most 4294967295 vertices can be indexed");
  }
  const uint64_t needed = vertices.rows * sizeof(Vec3f) + triangles.rows * sizeof(IndexTriple);
  if (held.bytes != 0 && needed > held.bytes) {
    return resource_exhausted(name + ": the mesh (" + std::to_string(vertices.rows) + " vertices, " +
                              std::to_string(triangles.rows) + " triangles) needs " + mib_text(needed) +
                              " in memory, more than the " + mib_text(held.bytes) + " allowed for it" +
                              (held.origin.empty() ? "" : " (" + held.origin + ")") +
                              "; allow more memory or split the mesh over several inputs");
  }
  std::vector<Vec3f> positions;
  OUTCORE_RETURN_IF_ERROR(convert_vertices(vertices, positions));
  std::vector<IndexTriple> indices;
  OUTCORE_RETURN_IF_ERROR(convert_triangles(triangles, vertices.rows, indices));
  return std::unique_ptr<TriangleSource>(
      std::make_unique<NpzMeshSource>(name, std::move(positions), std::move(indices)));
}

}  // namespace

Expected<std::unique_ptr<TriangleSource>> decode_npz_mesh(std::string_view bytes, const std::string& name,
                                                          const HeldMemoryLimit& held) {
  OUTCORE_ASSIGN_OR_RETURN(const Members members, decode_npz(bytes, name));
  return mesh_from_members(members, name, held);
}

Expected<std::unique_ptr<TriangleSource>> open_npz_mesh_file(const std::string& path,
                                                             const HeldMemoryLimit& held) {
  // Checked first: reading a FIFO would wait for a writer, a device never ends.
  struct stat info;
  if (::stat(path.c_str(), &info) != 0) return io_error_from_errno(path);
  if (!S_ISREG(info.st_mode)) {
    return invalid_argument(path + ": is " + file_type_name(info.st_mode) + ", not a regular file");
  }
  Members members;
  {
    // The archive's bytes go before the mesh is converted.
    OUTCORE_ASSIGN_OR_RETURN(const std::string bytes, read_whole_file(path));
    OUTCORE_ASSIGN_OR_RETURN(members, decode_npz(bytes, path));
  }
  return mesh_from_members(members, path, held);
}

}  // namespace outcore
