// EvictionPolicy: decides which resident, unpinned brick the cache evicts next.
// The cache tells the policy about every insert, access and erase; the policy
// only ranks. Policies are created by name (make_eviction_policy) so `trace` and
// `serve` can select them; "lru" now, more with the out-of-core work.
//
// Thread-safety: none of its own; the cache calls it under the cache's lock.
// Called once per brick acquisition, never per ray.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

class EvictionPolicy {
 public:
  virtual ~EvictionPolicy() = default;
  virtual void on_insert(uint32_t brick, uint64_t bytes) = 0;
  virtual void on_access(uint32_t brick) = 0;
  virtual void on_erase(uint32_t brick) = 0;
  // The brick to evict among those for which evictable(brick) is true, or
  // nothing if none is.
  virtual std::optional<uint32_t> choose_victim(const std::function<bool(uint32_t)>& evictable) = 0;
  virtual const std::string& name() const = 0;
};

Expected<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name);
std::vector<std::string> eviction_policy_names();

}  // namespace outcore
