// TemporaryDirectory: a directory created with a unique name and removed with
// everything in it when the owner is destroyed, unless released. The packer
// builds a store in one beside its output (readable by all, like the store it
// becomes, and named after its process so that a later pack can tell a dead
// pack's leftover from a running one); out-of-core readers keep their spill
// files in private ones, so a failed or interrupted run leaves nothing.
//
// Thread-safety: one owner; not copyable.
#pragma once

#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

class TemporaryDirectory {
 public:
  TemporaryDirectory() = default;
  ~TemporaryDirectory();
  TemporaryDirectory(const TemporaryDirectory&) = delete;
  TemporaryDirectory& operator=(const TemporaryDirectory&) = delete;

  // Creates `prefix` + a unique suffix, private to the user (mkdtemp, 0700);
  // the parent directory must exist.
  Status create(const std::string& prefix);
  // Creates `output.partial-PID-XXXXXX` beside the file or directory `output`,
  // with the permissions of any new directory (0777 less the umask: a store is
  // read by servers running as other users) and locked (flock) for as long as
  // this object owns it, so that find_stale_partials() never takes it for a
  // leftover.
  Status create_beside(const std::string& output);
  // Removes the directory now (also done by the destructor).
  void remove();
  const std::string& path() const { return path_; }
  // Keeps the directory (it was renamed into place); the destructor forgets it.
  void release();

 private:
  std::string path_;
  int lock_fd_ = -1;  // create_beside only: holds the flock
};

// A `.partial-PID-XXXXXX` directory beside `output` that create_beside made in
// a process that no longer runs: its pid is gone and nobody holds its lock.
struct StalePartial {
  std::string path;
  long pid = 0;
};
// The stale partial directories of `output` (none when its parent cannot be
// listed). Directories of running packs, of other outputs, and of older
// versions (no pid in the name) are never returned.
std::vector<StalePartial> find_stale_partials(const std::string& output);

// The directory for temporary files when none is given: $TMPDIR, else /tmp.
std::string default_temp_directory();

}  // namespace outcore
