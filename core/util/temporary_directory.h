// TemporaryDirectory: a directory created with a unique name (mkdtemp) and
// removed with everything in it when the owner is destroyed, unless released.
// The packer builds a store in one beside its output; out-of-core readers keep
// their spill files in one, so a failed or interrupted run leaves nothing.
//
// Thread-safety: one owner; not copyable.
#pragma once

#include <string>

#include "core/util/status.h"

namespace outcore {

class TemporaryDirectory {
 public:
  TemporaryDirectory() = default;
  ~TemporaryDirectory();
  TemporaryDirectory(const TemporaryDirectory&) = delete;
  TemporaryDirectory& operator=(const TemporaryDirectory&) = delete;

  // Creates `prefix` + a unique suffix; the parent directory must exist.
  Status create(const std::string& prefix);
  // Creates `output.partial-XXXXXX`, beside the file or directory `output`.
  Status create_beside(const std::string& output);
  // Removes the directory now (also done by the destructor).
  void remove();
  const std::string& path() const { return path_; }
  // Keeps the directory (it was renamed into place); the destructor forgets it.
  void release() { path_.clear(); }

 private:
  std::string path_;
};

// The directory for temporary files when none is given: $TMPDIR, else /tmp.
std::string default_temp_directory();

}  // namespace outcore
