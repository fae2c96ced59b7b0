// UpperWalks: the upper hierarchy in the forms the engine walks it (flat,
// 4-wide, 8-wide), made once when the engine opens, and next_window(), which
// fills a ray's window of upcoming bricks by the fastest form available. All
// forms give the same bricks with the same keys (upper_traversal.h).
// restricted_to() makes the walks of a part of the bricks (upper_part.h).
//
// Thread-safety: immutable after construction.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/upper/upper_part.h"
#include "core/upper/upper_traversal.h"
#include "core/upper/upper_wide8_traversal.h"

namespace outcore {

struct UpperWalks {
  // A hierarchy of a few bricks is traversed flat (all leaf boxes tested at
  // once), a larger one 4- or 8-wide: fewer branches.
  FlatLeaves flat;
  bool use_flat = false;
  WideUpper wide;
  WideUpper8 wide8;

  explicit UpperWalks(const UpperHierarchy& upper) {
    use_flat = make_flat_leaves(upper, flat);
    if (use_flat) return;
    make_wide_upper(upper, wide);
    make_wide_upper(upper, wide8);
  }

  // These walks over only the bricks marked in `in_part` (by brick id).
  UpperWalks restricted_to(std::span<const uint8_t> in_part) const {
    UpperWalks part = *this;
    if (use_flat) {
      restrict_flat_leaves(part.flat, in_part);
    } else {
      restrict_wide_upper(part.wide, in_part);
      restrict_wide_upper(part.wide8, in_part);
    }
    return part;
  }

  // The bricks after `last` that the ray enters within [tmin, limit], into
  // `window`; returns how many. Flat, 8-wide with AVX, else 4-wide.
  template <std::size_t N>
  uint32_t next_window(bool use_avx, const SlabRay& ray, float tmin, float limit, const BrickKey& last,
                       std::array<BrickKey, N>& window, uint64_t& nodes) const {
    if (use_flat) return next_bricks_flat(flat, ray, tmin, limit, last, window, nodes);
    if (use_avx) return next_bricks_wide8(wide8, ray, tmin, limit, last, window, nodes);
    return next_bricks_wide(wide, ray, tmin, limit, last, window, nodes);
  }
};

}  // namespace outcore
