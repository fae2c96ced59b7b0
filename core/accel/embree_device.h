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
// Attribution. The monitor callback fires on whatever thread allocates, and
// gets only the device's user pointer. So everything that makes Embree
// allocate or free (scene and geometry creation, commit, release) runs in a
// MeasuredSection, which attributes to itself what Embree allocates or frees
// on its own thread. A commit normally runs on that thread alone (in a
// one-thread TBB arena), so several bricks build at once, each measured
// exactly. One section at a time may instead commit in parallel (Embree's
// TBB tasks on other threads): it then also takes the bytes of threads that
// are in no section — only its own commit's helpers can be, since every other
// Embree call is in a section. Bytes that reach no section at all are counted
// as unattributed (a bug if ever non-zero; tested).
// Tracing (rtcIntersect*/rtcOccluded*) allocates nothing.
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

  // Bytes allocated (net) outside every section: 0 unless a call that makes
  // Embree allocate was left outside one.
  int64_t unattributed_bytes() const { return unattributed_bytes_.load(std::memory_order_relaxed); }

  // Counts what Embree allocates or frees on the calling thread while it
  // lives (and, when parallel(), on threads in no section). Sections never
  // nest on one thread.
  class MeasuredSection {
   public:
    // allow_parallel: may commit in parallel if no other section does.
    MeasuredSection(EmbreeDevice& device, bool allow_parallel);
    ~MeasuredSection();
    MeasuredSection(const MeasuredSection&) = delete;
    MeasuredSection& operator=(const MeasuredSection&) = delete;

    bool parallel() const { return parallel_lock_.owns_lock(); }
    // rtcCommitScene: in parallel when parallel(), else on this thread only.
    void commit(RTCScene scene);
    // Net bytes since the section began (negative when it freed more).
    int64_t delta_bytes() const { return delta_.load(std::memory_order_relaxed); }
    // Highest point of the section's bytes (>= 0).
    int64_t peak_delta_bytes() const { return peak_.load(std::memory_order_relaxed); }

   private:
    friend class EmbreeDevice;
    void add(int64_t bytes);

    EmbreeDevice& device_;
    std::unique_lock<std::mutex> parallel_lock_;
    std::atomic<int64_t> delta_{0};
    std::atomic<int64_t> peak_{0};
  };

 private:
  EmbreeDevice() = default;
  static bool memory_monitor(void* user, ssize_t bytes, bool post);
  static void error_callback(void* user, RTCError code, const char* message);

  RTCDevice device_ = nullptr;
  std::atomic<int64_t> live_bytes_{0};
  std::atomic<int64_t> unattributed_bytes_{0};
  std::mutex parallel_commit_mutex_;
  // The section committing in parallel, if any (set under the mutex).
  std::atomic<MeasuredSection*> parallel_section_{nullptr};
};

}  // namespace outcore
