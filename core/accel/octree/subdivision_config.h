// SubdivisionConfig<Node>: the options the regular subdivisions share (the
// octree, octree_builder.h, and the quadtree, quadtree/quadtree_builder.h):
// a leaf size that stops cutting and a depth limit, automatic by default,
// validated and parsed from key=value options with the tree's name
// (Node::kTreeName) in every error.
//
// Thread-safety: a plain value.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/util/parse_number.h"
#include "core/util/status.h"

namespace outcore {

template <class Node>
struct SubdivisionConfig {
  uint32_t max_leaf_size = 8;  // triangles a leaf may hold before it is cut
  // Levels below the root, at most Node::kMaxDepth - 1; 0: automatic,
  // ceil(log4(N / max_leaf_size)) + 2 (a surface's triangles fill about 4^d
  // cells at depth d, so leaves of max_leaf_size come about there).
  uint32_t max_depth = 0;

  Status validate() const {
    const std::string name = Node::kTreeName;
    if (max_leaf_size < 1 || max_leaf_size > 1024) {
      return invalid_argument(name + ": max_leaf_size must be in [1, 1024], got " +
                              std::to_string(max_leaf_size));
    }
    if (max_depth >= Node::kMaxDepth) {
      return invalid_argument(name + ": max_depth must be below " + std::to_string(Node::kMaxDepth) +
                              ", got " + std::to_string(max_depth));
    }
    return Status::Ok();
  }

  // Sets the option `key` (max_leaf_size, max_depth) from `value`: false
  // when `key` is none of them, an error naming `structure` when the value
  // is malformed.
  Expected<bool> parse_option(std::string_view structure, const std::string& key, const std::string& value) {
    if (key != "max_leaf_size" && key != "max_depth") return false;
    if (!parse_number(value, key == "max_leaf_size" ? max_leaf_size : max_depth)) {
      return invalid_argument("brick accel " + std::string(structure) + ": option " + key +
                              " must be a whole number, got '" + value + "'");
    }
    return true;
  }

  // The depth limit a build of n triangles uses.
  uint32_t depth_limit(uint64_t n) const {
    if (max_depth != 0) return max_depth;
    const double leaves = std::max(1.0, static_cast<double>(n) / max_leaf_size);
    const double automatic = std::ceil(std::log2(leaves) / 2.0) + 2.0;
    return std::min<uint32_t>(Node::kMaxDepth - 1, static_cast<uint32_t>(automatic));
  }
};

}  // namespace outcore
