// ProxySet: the occupancy proxies of every brick of one scene store, resident
// for the engine's lifetime (a few KiB per brick at the default resolution;
// memory_bytes() counts them). open() reads the store's proxies.bin
// (proxy_file.h) when it was written for this store (fingerprint of the
// manifest's bricks), this format version, resolution and margin, and its
// checksum holds; otherwise it builds the proxies by streaming every brick
// through SceneStore::load_brick on all cores and writes proxies.bin
// atomically (temporary file, fsync, rename) into the store directory, so a
// corrupt, truncated, stale or foreign file is rebuilt, never trusted. When
// the directory is not writable the proxies stay in memory only (a warning is
// logged). No other file of the store is ever written. A brick that cannot be
// read gets no proxy (it is never skipped; its query reports the error).
//
// Thread-safety: immutable after open()/build(); any number of threads may
// read it. Several processes may open the same store at once: each writes its
// own temporary file, and the renames are atomic.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/proxy/brick_proxy.h"
#include "core/proxy/proxy_builder.h"
#include "core/store/scene_store.h"
#include "core/util/status.h"

namespace outcore {

// How open() came by its proxies.
struct ProxyOpenReport {
  bool loaded = false;         // read from proxies.bin
  bool written = false;        // built, and proxies.bin (re)written
  std::string rebuild_reason;  // why proxies.bin was not used ("" when loaded)
  std::string write_error;     // why it could not be written ("" otherwise)
  double seconds = 0;          // reading, or building and writing
};

class ProxySet {
 public:
  ProxySet(const ProxyBuildConfig& config, std::vector<BrickProxy> proxies);

  static Expected<std::unique_ptr<const ProxySet>> open(const SceneStore& store,
                                                        const ProxyBuildConfig& config,
                                                        ProxyOpenReport* report = nullptr);
  // Builds in memory only (nothing written).
  static Expected<std::unique_ptr<const ProxySet>> build(const SceneStore& store,
                                                         const ProxyBuildConfig& config);

  const BrickProxy& brick(uint32_t id) const { return proxies_[id]; }
  uint32_t brick_count() const { return static_cast<uint32_t>(proxies_.size()); }
  const ProxyBuildConfig& config() const { return config_; }
  uint64_t memory_bytes() const { return memory_bytes_; }
  uint64_t active_voxels() const { return active_voxels_; }
  // Bricks that could not be read while building (never skipped); such a set
  // is not written to proxies.bin.
  uint32_t bricks_without_proxy() const { return bricks_without_proxy_; }

 private:
  ProxyBuildConfig config_;
  std::vector<BrickProxy> proxies_;
  uint64_t memory_bytes_ = 0;
  uint64_t active_voxels_ = 0;
  uint32_t bricks_without_proxy_ = 0;
};

}  // namespace outcore
