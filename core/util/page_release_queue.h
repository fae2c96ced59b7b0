// PageReleaseQueue: releases the pages of read-only file mappings
// (MappedFile::release_pages, MADV_DONTNEED) in batches instead of one call
// per mapping.
//
// Every call that drops page-table entries ends with a TLB flush that
// interrupts each other CPU running one of this process's threads; under a
// hypervisor that interrupt costs a VM exit on both sides, and the caller
// waits for the other vCPU to answer. The subtree tier releases an evicted
// brick's pages thousands of times a batch. Queued mappings are released
// together by one process_madvise() call (Linux >= 6.13 accepts
// MADV_DONTNEED for the calling process; >= 6.16 flushes once per call), or
// by one madvise() each where the kernel refuses that.
//
// The cost of batching is bounded: a queued mapping's pages stay mapped (in
// the process's RSS) until its batch is released, at most max_pending_bytes
// of mappings at any time. A mapping needed again before its release is
// taken back out (cancel): its pages were never dropped. A queued copy
// (MappedFile::copy) may also be taken out to hold another file (take): its
// populated pages are written over instead of released here and populated
// again elsewhere.
//
// Thread-safety: all member functions may be called concurrently; one mutex
// guards the queue and is never held across a system call (take()'s
// may_take runs under it).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "core/util/mapped_file.h"

namespace outcore {

struct PageReleaseCounters {
  uint64_t mappings_released = 0;  // mappings whose pages were dropped
  uint64_t batches = 0;            // system calls that dropped a batch (process_madvise) ...
  uint64_t single_calls = 0;       // ... or one mapping each (madvise)
  uint64_t cancelled = 0;          // mappings taken back before their release
  uint64_t taken = 0;              // copies taken out to hold another file (take)
};

class PageReleaseQueue {
 public:
  // Releases once max_pending_bytes of mappings or max_pending_mappings
  // mappings are queued (both at least 1; a queue of 1 releases at once).
  PageReleaseQueue(uint64_t max_pending_bytes, std::size_t max_pending_mappings);
  ~PageReleaseQueue();  // releases what is still queued
  PageReleaseQueue(const PageReleaseQueue&) = delete;
  PageReleaseQueue& operator=(const PageReleaseQueue&) = delete;

  // Queues `file`'s pages for release (the queue holds the mapping until
  // then); releases the batch when it is full.
  void release(std::shared_ptr<const MappedFile> file);
  // Takes `file` out of the queue if it is there (its pages stay mapped):
  // true when it was.
  bool cancel(const MappedFile* file);
  // Takes out of the queue (its pages stay mapped) a queued copy that can
  // hold a file of `bytes` bytes and has no more pages populated than that
  // file will: capacity() >= bytes, bytes() at most as many pages. Of those,
  // the one with most pages populated (fewest left to populate), among the
  // ones `may_take` accepts: it is asked under the queue's lock, must not
  // call the queue, and vets who else holds the copy (its use_count()). The
  // caller may then read_again(..., pages_kept = true) into it once nobody
  // else holds it. nullptr when none qualifies.
  std::shared_ptr<const MappedFile> take(
      std::size_t bytes, const std::function<bool(const std::shared_ptr<const MappedFile>&)>& may_take);
  // Releases everything queued now.
  void flush();

  uint64_t pending_bytes() const;
  PageReleaseCounters counters() const;

 private:
  // Under the lock: the queued mappings, leaving the queue empty.
  std::vector<std::shared_ptr<const MappedFile>> take_pending_locked();
  void release_now(std::vector<std::shared_ptr<const MappedFile>>& batch);

  const uint64_t max_pending_bytes_;
  const std::size_t max_pending_mappings_;
  mutable std::mutex mutex_;
  std::vector<std::shared_ptr<const MappedFile>> pending_;
  uint64_t pending_bytes_ = 0;
  PageReleaseCounters counters_;
  int pidfd_ = -1;                              // this process, for process_madvise
  std::atomic<bool> batched_calls_work_{true};  // cleared when the kernel refuses them
};

}  // namespace outcore
