// SceneStore: an opened scene store, and the engine's only way in to the data.
// open() reads and checks the manifest (format version, checksum, consistency)
// and that bricks.dat holds every brick's byte range; load_brick() reads one
// brick on demand and verifies its header and checksum, naming the brick in
// every error.
//
// Thread-safety: after open(), all const member functions may be called from
// any number of threads (reads use pread on one file descriptor).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/store/brick_data.h"
#include "core/store/manifest.h"
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

 private:
  SceneStore() = default;

  std::string directory_;
  Manifest manifest_;
  int brick_fd_ = -1;
  uint64_t bytes_on_disk_ = 0;
};

}  // namespace outcore
