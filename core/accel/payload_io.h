// Helpers the brick serialisers built on cereal share: zero padding, arrays
// of plain values written and read back, and the check that a brick handed
// to save() is the serialiser's structure with its triangle test.
//
// Thread-safety: pure functions.
#pragma once

#include <cereal/archives/binary.hpp>

#include <array>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "core/accel/brick_accel.h"
#include "core/accel/bvh/triangle_test_kind.h"
#include "core/util/status.h"

namespace outcore::payload_io {

inline constexpr uint64_t kMaxPadding = 64;

template <class Archive>
void write_zeros(Archive& archive, uint64_t bytes) {
  static constexpr std::array<char, kMaxPadding> kZeros{};
  archive(cereal::binary_data(kZeros.data(), bytes));
}

template <class Archive, class T>
void write_array(Archive& archive, std::span<const T> values) {
  if (!values.empty()) archive(cereal::binary_data(values.data(), values.size_bytes()));
}

// An empty vector's data() may be null, which memcpy must not be given.
template <class T>
void read_array(std::vector<T>& out, uint64_t count, std::span<const char> bytes, uint64_t offset) {
  out.resize(count);
  if (!out.empty()) std::memcpy(out.data(), bytes.data() + offset, out.size() * sizeof(T));
}

// The checks a payload starting with the triangle test byte begins with:
// INVALID_ARGUMENT "<what>: truncated ..." when it is shorter than its
// header, "<what>: triangle test ..." when the byte is not `test`.
inline Status check_header(std::span<const char> bytes, uint64_t header_bytes, TriangleTest test,
                           const std::string& what) {
  if (bytes.size() < header_bytes) {
    return invalid_argument(what + ": truncated (" + std::to_string(bytes.size()) + " bytes, no header)");
  }
  const uint8_t written = static_cast<uint8_t>(bytes[0]);
  if (written != static_cast<uint8_t>(test)) {
    return invalid_argument(what + ": triangle test " + std::to_string(written) + ", expected " +
                            std::string(triangle_test_name(test)));
  }
  return Status::Ok();
}

// `accel` as the serialiser's Accel type built with `test`, or
// INVALID_ARGUMENT naming what differs (`name`: "<structure> serialiser").
template <class Accel>
Expected<const Accel*> brick_to_save(const BrickAccel& accel, TriangleTest test, const std::string& name,
                                     const char* structure) {
  const auto* typed = dynamic_cast<const Accel*>(&accel);
  if (typed == nullptr) return invalid_argument(name + ": the brick is not a " + structure + " brick");
  if (typed->triangle_test() != test) {
    return invalid_argument(name + ": brick " + std::to_string(typed->brick_id()) + " uses triangle test " +
                            std::string(triangle_test_name(typed->triangle_test())) + ", not " +
                            std::string(triangle_test_name(test)));
  }
  return typed;
}

}  // namespace outcore::payload_io
