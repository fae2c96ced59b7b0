// .npy files (NumPy format 1.0/2.0/3.0) for the contract's rays and hits:
// rays are float32 C-order arrays of shape (N,6) or (N,8); hits are a
// structured array with fields t_hit <f4, geometry_id <u4, primitive_id <u4,
// u <f4, v <f4, ng (<f4, 3); any-hit answers are a (N,) bool array. Anything
// else (another dtype, Fortran order, a bad shape, a truncated file) is an
// INVALID_ARGUMENT / DATA_LOSS naming the file and what was found.
//
// Thread-safety: free functions, reentrant.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/util/status.h"

namespace outcore {

// The parsed header of a .npy file.
struct NpyHeader {
  std::string descr;  // e.g. "<f4" or the structured descr's text
  bool fortran_order = false;
  std::vector<uint64_t> shape;
  uint64_t data_offset = 0;  // bytes before the array data
};

// Parses the header from the first bytes of a file (at least the whole header).
Expected<NpyHeader> parse_npy_header(std::string_view bytes, const std::string& name);

// Any real or integer array (C order; <f4, <f8, <i1..<i8, <u1..<u8, |b1),
// every value converted to double: what the dynamic scene file's arrays
// need. INVALID_ARGUMENT naming `name` for another dtype or Fortran order.
struct NpyNumbers {
  std::vector<uint64_t> shape;
  std::vector<double> values;
  bool integral = false;  // the dtype was an integer or bool one
};
Expected<NpyNumbers> decode_numeric_npy(std::string_view bytes, const std::string& name);
std::string npy_shape_text(const std::vector<uint64_t>& shape);
// The data of a parsed array of items of item_bytes each, for readers that
// convert it themselves (no copy): DATA_LOSS naming `name` when the bytes
// hold less than the shape needs, INVALID_ARGUMENT when more.
Expected<std::string_view> npy_array_data(std::string_view bytes, const std::string& name,
                                          const NpyHeader& header, uint64_t item_bytes);

// A whole file's bytes (IO_ERROR naming it when it cannot be read).
Expected<std::string> read_whole_file(const std::string& path);

// Reads rays; (N,6) rows get tnear = 0, tfar = inf.
Expected<std::vector<Ray>> read_rays_npy(const std::string& path);
// Decodes rays from an in-memory .npy image (same checks as the file form).
Expected<std::vector<Ray>> decode_rays_npy(std::string_view bytes, const std::string& name);

Status write_rays_npy(const std::string& path, std::span<const Ray> rays);
Status write_hits_npy(const std::string& path, std::span<const Hit> hits);
Expected<std::vector<Hit>> read_hits_npy(const std::string& path);
Status write_bools_npy(const std::string& path, std::span<const uint8_t> flags);
// (N,3) float32: points such as secondary-ray origins (core/ray/spawn_origin.h).
Status write_points_npy(const std::string& path, std::span<const Vec3f> points);
Expected<std::vector<uint8_t>> read_bools_npy(const std::string& path);

// The descr string written for hits (numpy's repr of the structured dtype).
extern const char* const kHitsNpyDescr;

}  // namespace outcore
