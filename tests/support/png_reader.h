// A PNG decoder for the tests' reference pictures (`outcore render`): 8-bit
// RGB, non-interlaced, any number of IDAT chunks, all five row filters; CRCs
// checked. Anything else is refused with a message (it is not needed).
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace outcore::testing {

struct DecodedPng {
  uint32_t width = 0;
  uint32_t height = 0;
  std::vector<uint8_t> rgb;  // width x height x 3, top row first
  std::string error;         // empty on success
};

DecodedPng decode_png(const std::string& bytes);
DecodedPng read_png(const std::string& path);

}  // namespace outcore::testing
