#include "core/accel/embree_device.h"

#include <tbb/task_arena.h>

#include <cassert>
#include <string>

namespace outcore {
namespace {

// The message of the last error Embree reported on this thread (the callback
// runs on the thread whose API call failed).
thread_local std::string t_last_error_message;
// The section open on this thread, if any.
thread_local EmbreeDevice::MeasuredSection* t_section = nullptr;

const char* rtc_error_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "RTC_ERROR_NONE";
    case RTC_ERROR_UNKNOWN: return "RTC_ERROR_UNKNOWN";
    case RTC_ERROR_INVALID_ARGUMENT: return "RTC_ERROR_INVALID_ARGUMENT";
    case RTC_ERROR_INVALID_OPERATION: return "RTC_ERROR_INVALID_OPERATION";
    case RTC_ERROR_OUT_OF_MEMORY: return "RTC_ERROR_OUT_OF_MEMORY";
    case RTC_ERROR_UNSUPPORTED_CPU: return "RTC_ERROR_UNSUPPORTED_CPU";
    case RTC_ERROR_CANCELLED: return "RTC_ERROR_CANCELLED";
  }
  return "RTC_ERROR_?";
}

Status status_from_rtc_error(RTCError code, const std::string& what) {
  std::string message = what + ": Embree " + rtc_error_name(code);
  if (!t_last_error_message.empty()) message += " (" + t_last_error_message + ")";
  t_last_error_message.clear();
  switch (code) {
    case RTC_ERROR_NONE: return Status::Ok();
    case RTC_ERROR_OUT_OF_MEMORY: return resource_exhausted(std::move(message));
    case RTC_ERROR_INVALID_ARGUMENT: return invalid_argument(std::move(message));
    case RTC_ERROR_CANCELLED: return cancelled(std::move(message));
    default: return internal_error(std::move(message));
  }
}

}  // namespace

Expected<EmbreeDevice*> EmbreeDevice::instance() {
  // Created once, never destroyed (see the header).
  static const Expected<EmbreeDevice*> device = []() -> Expected<EmbreeDevice*> {
    auto* d = new EmbreeDevice();
    d->device_ = rtcNewDevice(nullptr);
    if (d->device_ == nullptr) {
      const RTCError code = rtcGetDeviceError(nullptr);
      delete d;
      return status_from_rtc_error(code == RTC_ERROR_NONE ? RTC_ERROR_UNKNOWN : code,
                                   "creating the Embree device");
    }
    rtcSetDeviceErrorFunction(d->device_, &EmbreeDevice::error_callback, d);
    rtcSetDeviceMemoryMonitorFunction(d->device_, &EmbreeDevice::memory_monitor, d);
    return d;
  }();
  return device;
}

bool EmbreeDevice::memory_monitor(void* user, ssize_t bytes, bool /*post*/) {
  // Embree calls this with bytes > 0 before it allocates and bytes < 0 after
  // it frees. Never refuse: budgets are enforced by the cache's reservations.
  auto* self = static_cast<EmbreeDevice*>(user);
  self->live_bytes_.fetch_add(bytes, std::memory_order_relaxed);
  MeasuredSection* section = t_section != nullptr ? t_section : self->parallel_section_.load();
  if (section != nullptr) {
    section->add(bytes);
  } else {
    self->unattributed_bytes_.fetch_add(bytes, std::memory_order_relaxed);
  }
  return true;
}

void EmbreeDevice::error_callback(void* /*user*/, RTCError /*code*/, const char* message) {
  t_last_error_message = message != nullptr ? message : "";
}

Status EmbreeDevice::take_error(const std::string& what) const {
  const RTCError code = rtcGetDeviceError(device_);
  if (code == RTC_ERROR_NONE) {
    t_last_error_message.clear();
    return Status::Ok();
  }
  return status_from_rtc_error(code, what);
}

EmbreeDevice::MeasuredSection::MeasuredSection(EmbreeDevice& device, bool allow_parallel) : device_(device) {
  assert(t_section == nullptr && "sections never nest");
  t_section = this;
  if (allow_parallel) {
    parallel_lock_ = std::unique_lock<std::mutex>(device.parallel_commit_mutex_, std::try_to_lock);
    if (parallel_lock_.owns_lock()) device.parallel_section_.store(this);
  }
}

EmbreeDevice::MeasuredSection::~MeasuredSection() {
  if (parallel()) device_.parallel_section_.store(nullptr);
  t_section = nullptr;
}

void EmbreeDevice::MeasuredSection::add(int64_t bytes) {
  const int64_t now = delta_.fetch_add(bytes, std::memory_order_relaxed) + bytes;
  int64_t peak = peak_.load(std::memory_order_relaxed);
  while (now > peak && !peak_.compare_exchange_weak(peak, now, std::memory_order_relaxed)) {
  }
}

void EmbreeDevice::MeasuredSection::commit(RTCScene scene) {
  if (parallel()) {
    // Isolated: while this thread waits inside the commit it must not pick
    // up an outer task (another brick's build, say) that would open a second
    // section on it.
    tbb::this_task_arena::isolate([&] { rtcCommitScene(scene); });
    return;
  }
  // One slot, taken by this thread: Embree's tasks for this commit all run
  // here, so every byte it allocates is seen by this thread's section.
  static thread_local tbb::task_arena one_thread(1);
  one_thread.execute([&] { rtcCommitScene(scene); });
}

}  // namespace outcore
