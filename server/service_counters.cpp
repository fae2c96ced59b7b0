#include "server/service_counters.h"

#include <cstddef>
#include <type_traits>

namespace outcore::server {

namespace {

// Times are kept as whole nanoseconds: atomics add integers.
template <class T>
uint64_t to_counter(T value) {
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<uint64_t>(value * 1e9);
  } else {
    return value;
  }
}

template <class T>
T from_counter(uint64_t counter) {
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<T>(counter) * 1e-9;
  } else {
    return counter;
  }
}

}  // namespace

void AtomicServiceCounters::count_request(bool failed, bool cancelled) {
  requests_.fetch_add(1, std::memory_order_relaxed);
  if (failed) failed_requests_.fetch_add(1, std::memory_order_relaxed);
  if (cancelled) cancelled_requests_.fetch_add(1, std::memory_order_relaxed);
}

void AtomicServiceCounters::add_answered(const QueryStats& stats) {
  std::size_t i = 0;
  for_each_field(stats, [&](const StatsField& field, const auto& value) {
    if (field.server == StatsServer::kYes)
      answered_[i].fetch_add(to_counter(value), std::memory_order_relaxed);
    ++i;
  });
}

ServiceCounters AtomicServiceCounters::snapshot() const {
  ServiceCounters c;
  c.requests = requests_.load(std::memory_order_relaxed);
  c.failed_requests = failed_requests_.load(std::memory_order_relaxed);
  c.cancelled_requests = cancelled_requests_.load(std::memory_order_relaxed);
  std::size_t i = 0;
  for_each_field(c.answered, [&](const StatsField& field, auto& value) {
    if (field.server == StatsServer::kYes) {
      value = from_counter<std::remove_reference_t<decltype(value)>>(
          answered_[i].load(std::memory_order_relaxed));
    }
    ++i;
  });
  return c;
}

}  // namespace outcore::server
