// Reading single figures out of the JSON the `outcore` commands write
// (trace --stats-json, ...), for the tests: no parser, just the value after a
// key, which is enough for their flat, known output.
//
// Thread-safety: pure functions; failures are gtest failures.
#pragma once

#include <cstdint>
#include <string>

namespace outcore::testing {

// The unsigned integer after the `occurrence`-th "key": in `json` (0 and a
// gtest failure when there is none).
uint64_t json_uint(const std::string& json, const std::string& key, int occurrence = 0);

}  // namespace outcore::testing
