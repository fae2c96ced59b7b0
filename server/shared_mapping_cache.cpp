#include "server/shared_mapping_cache.h"

#include <algorithm>
#include <utility>

namespace outcore::server {

Expected<std::shared_ptr<SharedMemoryObject>> SharedMappingCache::open(const std::string& name,
                                                                       std::size_t map_bytes) {
  OUTCORE_ASSIGN_OR_RETURN(const SharedObjectIdentity identity, SharedMemoryObject::identify(name));
  // Dropped mappings are unmapped after the lock is released (declared first).
  std::vector<std::shared_ptr<SharedMemoryObject>> dropped;
  // Under the lock: drops the mappings no name refers to any more and, when
  // `stale_name` is given, those of that name, keeping their objects in
  // `dropped`.
  const auto drop_locked = [&](const std::string* stale_name) {
    for (auto it = entries_.begin(); it != entries_.end();) {
      if ((stale_name != nullptr && it->object->name() == *stale_name) || it->object->unlinked()) {
        dropped.push_back(std::move(it->object));
        it = entries_.erase(it);
      } else {
        ++it;
      }
    }
  };
  {
    std::lock_guard lock(mutex_);
    drop_locked(nullptr);
    for (Entry& entry : entries_) {
      const SharedMemoryObject& kept = *entry.object;
      if (kept.name() == name && kept.identity() == identity &&
          kept.mapped_bytes() >= std::min<uint64_t>(map_bytes, identity.size)) {
        entry.last_use = ++clock_;
        ++reused_;
        return entry.object;
      }
    }
  }
  // Mapped outside the lock (MAP_POPULATE takes milliseconds).
  OUTCORE_ASSIGN_OR_RETURN(SharedMemoryObject opened, SharedMemoryObject::open(name, map_bytes));
  auto object = std::make_shared<SharedMemoryObject>(std::move(opened));
  std::lock_guard lock(mutex_);
  ++mapped_;
  if (max_objects_ == 0) return object;
  // Whatever this name mapped before is stale or too small.
  drop_locked(&name);
  if (entries_.size() >= max_objects_) {
    const auto oldest =
        std::min_element(entries_.begin(), entries_.end(),
                         [](const Entry& a, const Entry& b) { return a.last_use < b.last_use; });
    dropped.push_back(std::move(oldest->object));
    entries_.erase(oldest);
  }
  entries_.push_back({object, ++clock_});
  return object;
}

uint64_t SharedMappingCache::reused() const {
  std::lock_guard lock(mutex_);
  return reused_;
}

uint64_t SharedMappingCache::mapped() const {
  std::lock_guard lock(mutex_);
  return mapped_;
}

std::size_t SharedMappingCache::kept() const {
  std::lock_guard lock(mutex_);
  return entries_.size();
}

}  // namespace outcore::server
