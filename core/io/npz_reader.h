// Reading NumPy .npz archives (numpy.savez and savez_compressed): a ZIP file
// whose members NAME.npy are .npy files. Stored and deflated members are
// read, ZIP64 sizes and offsets included; anything else (encryption, another
// compression, a member running past the file, a checksum mismatch) is an
// error naming the archive and the member.
//
// Thread-safety: free functions, reentrant.
#pragma once

#include <map>
#include <string>

#include "core/util/status.h"

namespace outcore {

// Member name without ".npy" -> that member's bytes (a whole .npy file).
Expected<std::map<std::string, std::string>> read_npz(const std::string& path);
// The same from the archive's bytes; `name` is used in errors.
Expected<std::map<std::string, std::string>> decode_npz(std::string_view bytes, const std::string& name);

}  // namespace outcore
