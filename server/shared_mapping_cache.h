// SharedMappingCache: the shared-memory objects of recent shared calls
// (proto SharedPayload), kept mapped between calls. A client reuses one
// object for call after call; mapping its rays and answers again each time
// (mmap with MAP_POPULATE, then munmap) is a noticeable share of a large
// call (docs/BENCHMARKS_HISTORY.md, "kept mappings"). A call whose name still names the same object (same
// device, inode and size: one shm_open and fstat) and whose ranges lie inside the kept mapping reuses it;
// otherwise the object is mapped afresh and kept. The token is still checked on every call, by the caller.
//
// Bounds: at most max_objects mappings (least recently used dropped first),
// and a kept mapping whose object was unlinked (its client closed it or
// exited) is dropped at the next open(), so that the server does not keep
// its memory allocated; until then it holds up to max_objects objects' pages.
//
// Thread-safety: open() may be called from several threads; a returned
// object stays valid while the caller holds it, even if the cache drops it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/util/shared_memory.h"
#include "core/util/status.h"

namespace outcore::server {

class SharedMappingCache {
 public:
  explicit SharedMappingCache(std::size_t max_objects = 4) : max_objects_(max_objects) {}

  // The object `name` names, mapped over at least its first map_bytes bytes
  // (or all of it when smaller). Errors as SharedMemoryObject::open's.
  Expected<std::shared_ptr<SharedMemoryObject>> open(const std::string& name, std::size_t map_bytes);

  // Calls served by a kept mapping, and mappings made.
  uint64_t reused() const;
  uint64_t mapped() const;
  std::size_t kept() const;

 private:
  struct Entry {
    std::shared_ptr<SharedMemoryObject> object;
    uint64_t last_use = 0;
  };

  const std::size_t max_objects_;
  mutable std::mutex mutex_;  // taken twice per shared call, never per ray
  std::vector<Entry> entries_;
  uint64_t clock_ = 0;
  uint64_t reused_ = 0;
  uint64_t mapped_ = 0;
};

}  // namespace outcore::server
