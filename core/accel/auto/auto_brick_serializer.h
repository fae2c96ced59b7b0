// The auto builder's payload for the subtree tier: a 64-byte header naming
// the chosen candidate and the brick's features, then that candidate's own
// payload (which therefore stays 64-byte aligned and may be read in place).
//
//   0  u32  magic 0x3141434f ("OCA1")
//   4  u32  candidate index (into the builder's candidates)
//   8  u64  bytes of the candidate's payload (the rest of the payload)
//   16 f64  density_spread, 24 f64 flatness, 32 f64 area_ratio
//   40..63  zero
//
// The structure key names every candidate's own key, so a tier written with
// other candidates or options is never read; the cost profile is not in it
// (it changes choices, never answers).
//
// Thread-safety: as BrickSerializer.
#pragma once

#include <memory>

#include "core/accel/brick_serializer.h"

namespace outcore {

class AutoBrickBuilder;

// nullptr when a candidate cannot be serialised. `builder` must outlive it.
std::unique_ptr<BrickSerializer> make_auto_brick_serializer(const AutoBrickBuilder& builder);

}  // namespace outcore
