// SceneStore: an opened scene store, and the engine's only way in to the data.
// open() reads and checks the manifest (format version, checksum, consistency)
// and that bricks.dat holds every brick's byte range; load_brick() reads one
// brick on demand and verifies its header and checksum, naming the brick in
// every error. The brick file stays open from open() on, so a store replaced
// or removed on disk afterwards (pack --force) is still read whole, never
// mixed with its successor; check_unchanged_on_disk() tells that it happened.
//
// Thread-safety: after open(), all const member functions may be called from
// any number of threads (reads use pread on one file descriptor).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/store/brick_data.h"
#include "core/store/manifest.h"
#include "core/util/mapped_file.h"
#include "core/util/status.h"

namespace outcore {

class SceneStore {
 public:
  static Expected<std::shared_ptr<const SceneStore>> open(const std::string& directory);
  ~SceneStore();
  SceneStore(const SceneStore&) = delete;
  SceneStore& operator=(const SceneStore&) = delete;

  const std::string& directory() const { return directory_; }
  const Manifest& manifest() const { return manifest_; }
  uint32_t brick_count() const { return static_cast<uint32_t>(manifest_.bricks.size()); }
  // Manifest plus brick data file.
  uint64_t bytes_on_disk() const { return bytes_on_disk_; }

  // Reads brick `brick_id` into `out` (reusing its capacity). DATA_LOSS names the
  // brick when its bytes are truncated or altered.
  Status load_brick(uint32_t brick_id, BrickData& out) const;

  // FAILED_PRECONDITION naming the directory when the store on disk is no
  // longer the one opened: its manifest or brick file was replaced (another
  // pack --force) or removed. Two stat calls; reads from this store are
  // unaffected either way.
  Status check_unchanged_on_disk() const;

 private:
  SceneStore() = default;

  std::string directory_;
  Manifest manifest_;
  int brick_fd_ = -1;
  // Which files the paths named when the store was opened.
  FileIdentity manifest_identity_;
  FileIdentity brick_file_identity_;
  uint64_t bytes_on_disk_ = 0;
};

}  // namespace outcore
