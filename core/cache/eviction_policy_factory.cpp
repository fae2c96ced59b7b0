#include <memory>
#include <string>
#include <vector>

#include "core/cache/arc_policy.h"
#include "core/cache/clock_policy.h"
#include "core/cache/eviction_policy.h"
#include "core/cache/gdsf_policy.h"
#include "core/cache/lfu_policy.h"
#include "core/cache/lru_policy.h"
#include "core/cache/s3fifo_policy.h"
#include "core/cache/schedule_policy.h"

namespace outcore {

std::vector<std::string> eviction_policy_names() {
  return {"lru", "clock", "lfu", "arc", "s3fifo", "gdsf", "schedule"};
}

Expected<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name) {
  std::unique_ptr<EvictionPolicy> policy;
  if (name == "lru") policy = std::make_unique<LruPolicy>();
  if (name == "clock") policy = std::make_unique<ClockPolicy>();
  if (name == "lfu") policy = std::make_unique<LfuPolicy>();
  if (name == "arc") policy = std::make_unique<ArcPolicy>();
  if (name == "s3fifo") policy = std::make_unique<S3FifoPolicy>();
  if (name == "gdsf") policy = std::make_unique<GdsfPolicy>();
  if (name == "schedule") policy = std::make_unique<SchedulePolicy>();
  if (policy) return policy;
  std::string known;
  for (const std::string& n : eviction_policy_names()) known += (known.empty() ? "" : ", ") + n;
  return not_found("unknown eviction policy '" + name + "' (known: " + known + ")");
}

}  // namespace outcore
