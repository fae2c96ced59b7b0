// write_file_atomically: replaces a file with new contents so that a reader,
// or whoever finds the file after a failure (disk full, a size limit, a
// crash), sees the old file whole or the new one whole, never a truncated
// mix. The bytes go to a hidden temporary in the same directory (a rename
// across file systems is not atomic), which is renamed over the target once
// everything is written; on any failure the temporary is removed and the
// target left as it was.
//
// A target that exists and is not a regular file (a device such as
// /dev/stdout, a FIFO) cannot be replaced by a rename: it is written
// directly. A symbolic link is followed: the file it names is replaced.
//
// Thread-safety: reentrant; concurrent writers of the same target each
// leave a whole file (the last rename wins).
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace outcore {

struct AtomicWriteOptions {
  // fsync the temporary before the rename (the new contents survive a power
  // loss once the call returns).
  bool sync = false;
  // The new file's permission bits; negative: 0666 under the umask, as a
  // plain open(O_CREAT) would make it.
  int mode = -1;
};

// Writes the concatenation of `parts` to `path` as described above. Errors
// are IO_ERROR naming the path and the system's reason.
Status write_file_atomically(const std::string& path, std::span<const std::string_view> parts,
                             const AtomicWriteOptions& options = {});

}  // namespace outcore
