// The end of a pack: the manifest (inputs, bricks, the fixed upper hierarchy
// built over the brick bounds) is written into the directory being built,
// synced, and the directory swapped into place at the output
// (AtomicDirectory, core/util/atomic_file.h), after checking once more that
// what is at the output may be replaced: it may have changed while the pack
// ran.
//
// Thread-safety: free function; one pack, one thread.
#pragma once

#include <filesystem>
#include <vector>

#include "core/store/manifest.h"
#include "core/store/pack_context.h"
#include "core/util/atomic_file.h"

namespace outcore::packing {

// Builds the manifest of `scan` and `bricks` (moved from), writes it into
// `store`, and commits `store` at `output`. Returns the manifest.
Expected<Manifest> commit_store(const PackContext& context, const ScanResult& scan,
                                std::vector<BrickRecord> bricks, AtomicDirectory& store,
                                const std::filesystem::path& output);

}  // namespace outcore::packing
