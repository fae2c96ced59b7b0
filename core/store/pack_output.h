// Where a pack may write: the options are checked up front, and the output
// path must be free, or (--force) hold an Outcore store that holds no input of
// this pack; anything else is refused, so that --force can never delete
// someone's files. Also the clean-up of temporary directories that packs
// which died left beside the output.
//
// Thread-safety: free functions; reentrant.
#pragma once

#include <filesystem>
#include <string>

#include "core/store/scene_packer.h"
#include "core/util/status.h"

namespace outcore::packing {

// Absolute, and "scene/" names the directory scene, not an entry inside it.
std::filesystem::path normalized_output(const std::string& output);
// The options' ranges, then check_output() on the normalized output.
Status validate_pack_options(const PackOptions& options);
// OK when nothing is at `output`, or --force is given and it may be replaced.
Status check_output(const PackOptions& options, const std::filesystem::path& output);
// Removes (and logs) the temporary directories that dead packs left beside
// `output`.
void remove_stale_partials(const std::filesystem::path& output);

}  // namespace outcore::packing
