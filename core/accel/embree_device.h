// EmbreeDevice: the process's one RTCDevice, created on first use, with two
// hooks every Embree brick relies on:
//
// - Errors: Embree's error callback records the message of the calling
//   thread's last error; take_error() turns it (with rtcGetDeviceError's code)
//   into a Status: RTC_ERROR_OUT_OF_MEMORY -> RESOURCE_EXHAUSTED,
//   RTC_ERROR_INVALID_ARGUMENT -> INVALID_ARGUMENT, anything else -> INTERNAL.
//   Errors raised inside a commit's TBB tasks are rethrown by Embree on the
//   committing thread, so the thread that made the call sees them.
// - Memory: the memory-monitor callback (rtcSetDeviceMemoryMonitorFunction)
//   feeds one atomic counter of the bytes Embree reports as held by all
//   objects of the device (its BVH nodes, leaves and build-time arrays; the
//   small scene and geometry objects themselves are not reported, see
//   EmbreeBrickAccel) and its running maximum.
//
// Attribution. The monitor callback fires on whatever thread allocates —
// during a commit mostly TBB worker threads that may at the same time be
// helping another commit — so bytes cannot be attributed to a scene through
// thread-local counters or the callback's arguments (it gets only the device's
// user pointer). Instead, everything that makes Embree allocate or free
// (scene and geometry creation, commit, release) runs inside an
// ExclusiveSection, which holds one process-wide mutex: while it is held no
// other scene's bytes can move, so the counter's change (and its peak) over the
// section is exactly that scene's. The price is that brick builds are
// serialised; each build is itself parallel (Embree uses TBB inside commit).
// Tracing (rtcIntersect*/rtcOccluded*) allocates nothing and never takes the
// mutex.
//
// Thread-safety: instance() and all member functions may be called from any
// thread. The device is never released: scenes released during static
// destruction still find it alive.
#pragma once

#include <embree3/rtcore.h>

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>

#include "core/util/status.h"

namespace outcore {

class EmbreeDevice {
 public:
  // The device, created on the first call (thread-safe). Fails, every time,
  // with the creation error if Embree cannot create a device.
  static Expected<EmbreeDevice*> instance();

  RTCDevice handle() const { return device_; }

  // Bytes Embree currently reports as allocated by objects of this device.
  int64_t live_bytes() const { return live_bytes_.load(std::memory_order_relaxed); }

  // The calling thread's pending Embree error (clearing it) as a Status with
  // `what` as context, or OK when there is none.
  Status take_error(const std::string& what) const;

  // Holds the process-wide allocation mutex; measures the bytes Embree
  // allocates or frees while it is held. Sections never nest.
  class ExclusiveSection {
   public:
    explicit ExclusiveSection(EmbreeDevice& device);
    ExclusiveSection(const ExclusiveSection&) = delete;
    ExclusiveSection& operator=(const ExclusiveSection&) = delete;

    // Net change of the device's bytes since the section began (negative
    // when it freed more than it allocated).
    int64_t delta_bytes() const;
    // Highest point of the device's bytes during the section, minus the bytes
    // at its start (>= 0).
    int64_t peak_delta_bytes() const;

   private:
    std::lock_guard<std::mutex> lock_;
    EmbreeDevice& device_;
    int64_t start_bytes_;
  };

 private:
  EmbreeDevice() = default;
  static bool memory_monitor(void* user, ssize_t bytes, bool post);
  static void error_callback(void* user, RTCError code, const char* message);

  RTCDevice device_ = nullptr;
  std::atomic<int64_t> live_bytes_{0};
  std::atomic<int64_t> peak_bytes_{0};
  std::mutex allocation_mutex_;
};

}  // namespace outcore
