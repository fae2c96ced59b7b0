// The one way Outcore replaces what is on disk so that a reader, or whoever
// finds the files after a failure (disk full, a size limit, a crash), sees
// the old version whole or the new one whole, never a truncated mix:
//
// - AtomicFile: new bytes go to a hidden temporary ".NAME.tmp-PID-N" in the
//   target's directory (a rename across file systems is not atomic), which is
//   optionally fsynced and then renamed over the target; on any failure, or
//   when the owner gives up, the temporary is removed and the target left as
//   it was. Used by proxies.bin (write_file_atomically) and the subtree tier
//   (which writes the temporary with its own writer).
// - write_file_atomically: AtomicFile for bytes already in memory.
// - AtomicDirectory: a directory built beside its target and renamed into
//   place, an existing target moved aside first and removed once the new one
//   is there. Used by the packer's store commit.
//
// Thread-safety: reentrant; one owner per object. Concurrent writers of the
// same target each leave a whole file (the last rename wins).
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "core/util/status.h"
#include "core/util/temporary_directory.h"

namespace outcore {

struct AtomicWriteOptions {
  // fsync the temporary before the rename (the new contents survive a power
  // loss once the call returns).
  bool sync = false;
  // The new file's permission bits; negative: 0666 under the umask, as a
  // plain open(O_CREAT) would make it.
  int mode = -1;
};

class AtomicFile {
 public:
  AtomicFile() = default;
  ~AtomicFile();  // discard() unless committed
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  // Names a fresh temporary beside `target` and creates nothing: for writers
  // that create the file themselves (as a new file) at temp_path().
  void prepare(const std::string& target);
  // Creates the temporary, open for write(); a name an earlier process with
  // our pid left is skipped. Error: "cannot create a temporary file beside
  // TARGET: reason".
  Status create(const std::string& target, const AtomicWriteOptions& options = {});
  const std::string& temp_path() const { return temp_; }
  const std::string& target() const { return target_; }
  // Appends to the temporary that create() opened.
  Status write(std::string_view bytes);
  // Closes the temporary if create() opened it (setting its mode, fsyncing
  // it when asked), then renames it over the target. On failure the
  // temporary is removed and the target is untouched.
  Status commit();
  // Removes the temporary (closing it first).
  void discard();

 private:
  friend Status write_file_atomically(const std::string&, std::span<const std::string_view>,
                                      const AtomicWriteOptions&);
  Status create_named(const std::string& target, const AtomicWriteOptions& options, const std::string& name);

  std::string target_;
  std::string name_;  // the target as the caller named it, for messages
  std::string temp_;
  AtomicWriteOptions options_;
  int fd_ = -1;
};

// Writes the concatenation of `parts` to `path` through an AtomicFile. A
// target that exists and is not a regular file (a device such as
// /dev/stdout, a FIFO) cannot be replaced by a rename: it is written
// directly. A symbolic link is followed: the file it names is replaced.
// Errors are IO_ERROR naming the path and the system's reason.
Status write_file_atomically(const std::string& path, std::span<const std::string_view> parts,
                             const AtomicWriteOptions& options = {});

// fsync()s one file. Error: "cannot sync PATH: reason".
Status sync_file(const std::string& path);

class AtomicDirectory {
 public:
  // Creates the directory to fill beside `target`
  // (TemporaryDirectory::create_beside: TARGET.partial-PID-XXXXXX, 0777 less
  // the umask, locked against find_stale_partials while this object has it).
  Status create(const std::string& target);
  const std::string& path() const { return temp_.path(); }
  // Renames the directory to the target given to create(). With `sync`, the
  // directory is fsynced before and its parent after the rename (the caller
  // syncs the files inside). An existing target is moved aside to
  // TARGET.replaced-PID[-N] first, put back if the rename fails, and removed
  // after. `what` names the directory in messages ("cannot rename the new
  // WHAT into TARGET: reason"). Not committed (an error, or never called):
  // the directory is removed when this object goes.
  Status commit(bool sync, const std::string& what);

 private:
  std::string target_;
  TemporaryDirectory temp_;
};

}  // namespace outcore
