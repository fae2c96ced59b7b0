#include <memory>
#include <string>
#include <vector>

#include "core/cache/eviction_policy.h"
#include "core/cache/lru_policy.h"

namespace outcore {

std::vector<std::string> eviction_policy_names() {
  return {"lru"};
}

Expected<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name) {
  if (name == "lru") return std::unique_ptr<EvictionPolicy>(std::make_unique<LruPolicy>());
  std::string known;
  for (const std::string& n : eviction_policy_names()) known += (known.empty() ? "" : ", ") + n;
  return not_found("unknown eviction policy '" + name + "' (known: " + known + ")");
}

}  // namespace outcore
