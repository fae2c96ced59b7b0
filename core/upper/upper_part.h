// The upper hierarchy's walk forms restricted to a part of the scene's
// bricks (QueryOptions::only_bricks: what a replica that owns some bricks
// traces). Each wide node keeps, in their order, only the children whose
// subtree holds a brick of the part (its count shrinks: lanes past it are
// computed and never reported, as in every wide node), and the flat leaves
// only the part's bricks. A walk then never enters a subtree without one of
// the part's bricks, and a ray's window holds the part's bricks with the
// keys the whole hierarchy gives them (each key comes from the brick's own
// box by the same operations, whichever siblings are left).
//
// Thread-safety: pure functions over the caller's copies.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/upper/upper_traversal.h"

namespace outcore {

// Keeps in `wide` only the children whose subtree holds a brick marked in
// `in_part` (indexed by brick id). A node's children come after it
// (make_wide_upper), so one pass from the last node up settles each node's
// children before the node.
template <uint32_t W>
void restrict_wide_upper(WideUpperOf<W>& wide, std::span<const uint8_t> in_part) {
  std::vector<uint8_t> holds_part(wide.nodes.size(), 0);
  for (std::size_t i = wide.nodes.size(); i-- > 0;) {
    typename WideUpperOf<W>::Node& node = wide.nodes[i];
    uint32_t kept = 0;
    uint32_t leaf_bits = 0;
    for (uint32_t k = 0; k < node.count; ++k) {
      const bool leaf = (node.leaf_bits >> k & 1u) != 0;
      if (!(leaf ? in_part[node.child[k]] != 0 : holds_part[node.child[k]] != 0)) continue;
      for (int axis = 0; axis < 3; ++axis) {
        node.lo[axis][kept] = node.lo[axis][k];
        node.hi[axis][kept] = node.hi[axis][k];
      }
      node.child[kept] = node.child[k];
      if (leaf) leaf_bits |= 1u << kept;
      ++kept;
    }
    node.count = kept;
    node.leaf_bits = leaf_bits;
    holds_part[i] = kept > 0;
  }
}

// Keeps in `flat` only the leaves of bricks marked in `in_part`.
inline void restrict_flat_leaves(FlatLeaves& flat, std::span<const uint8_t> in_part) {
  uint32_t kept = 0;
  for (uint32_t j = 0; j < flat.count; ++j) {
    if (in_part[flat.brick[j]] == 0) continue;
    for (int axis = 0; axis < 3; ++axis) {
      flat.lo[axis][kept] = flat.lo[axis][j];
      flat.hi[axis][kept] = flat.hi[axis][j];
    }
    flat.brick[kept++] = flat.brick[j];
  }
  for (uint32_t j = kept; j < flat.count; ++j) flat.brick[j] = kInvalidId;
  flat.count = kept;
}

}  // namespace outcore
