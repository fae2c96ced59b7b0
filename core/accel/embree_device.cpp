#include "core/accel/embree_device.h"

#include <string>

namespace outcore {
namespace {

// The message of the last error Embree reported on this thread (the callback
// runs on the thread whose API call failed).
thread_local std::string t_last_error_message;

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
  const int64_t now = self->live_bytes_.fetch_add(bytes, std::memory_order_relaxed) + bytes;
  if (bytes > 0) {
    int64_t peak = self->peak_bytes_.load(std::memory_order_relaxed);
    while (now > peak && !self->peak_bytes_.compare_exchange_weak(peak, now, std::memory_order_relaxed)) {
    }
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

EmbreeDevice::ExclusiveSection::ExclusiveSection(EmbreeDevice& device)
    : lock_(device.allocation_mutex_), device_(device), start_bytes_(device.live_bytes()) {
  // Only this section moves the counter now, so the peak restarts from here.
  device_.peak_bytes_.store(start_bytes_, std::memory_order_relaxed);
}

int64_t EmbreeDevice::ExclusiveSection::delta_bytes() const {
  return device_.live_bytes() - start_bytes_;
}

int64_t EmbreeDevice::ExclusiveSection::peak_delta_bytes() const {
  const int64_t peak = device_.peak_bytes_.load(std::memory_order_relaxed);
  return peak > start_bytes_ ? peak - start_bytes_ : 0;
}

}  // namespace outcore
