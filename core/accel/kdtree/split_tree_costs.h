// SplitTreeCosts: the SAH constants and depth limit both split-plane tree
// builders take (the kd-tree's and the BSP's Config derive from it), their
// checks, the automatic depth limit, and the factory's parsing of them as
// brick structure options.
//
// Thread-safety: a plain value; functions are pure.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace outcore {

struct SplitTreeCosts {
  // pbrt-v3's constants (traversal 1, intersection 80, empty bonus 0.5).
  float traversal_cost = 1.0f;
  float intersection_cost = 80.0f;
  float empty_bonus = 0.5f;
  // 0: 8 + 1.3 log2(N) (pbrt-v3), at most the tree's deepest.
  uint32_t max_depth = 0;

  // INVALID_ARGUMENT "<tree>: <option> ..." when a constant is out of range
  // or max_depth exceeds `deepest`.
  Status validate(std::string_view tree, uint32_t deepest) const;
  // The depth limit a build of n triangles uses.
  uint32_t depth_limit(uint64_t n, uint32_t deepest) const;
  // Sets the option `key` (traversal_cost, intersection_cost, empty_bonus,
  // max_depth) from `value`: false when `key` is none of them, an error
  // naming `structure` when the value is malformed.
  Expected<bool> parse_option(std::string_view structure, const std::string& key, const std::string& value);
};

}  // namespace outcore
