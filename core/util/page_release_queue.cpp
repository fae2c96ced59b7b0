#include "core/util/page_release_queue.h"

#include <sys/mman.h>
#include <sys/syscall.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <utility>

namespace outcore {
namespace {

// process_madvise() takes at most UIO_MAXIOV ranges.
constexpr std::size_t kMaxRangesPerCall = 1024;

}  // namespace

PageReleaseQueue::PageReleaseQueue(uint64_t max_pending_bytes, std::size_t max_pending_mappings)
    : max_pending_bytes_(std::max<uint64_t>(max_pending_bytes, 1)),
      max_pending_mappings_(std::clamp<std::size_t>(max_pending_mappings, 1, kMaxRangesPerCall)) {
  pidfd_ = static_cast<int>(::syscall(SYS_pidfd_open, ::getpid(), 0));
  if (pidfd_ < 0) batched_calls_work_ = false;
  pending_.reserve(max_pending_mappings_);
}

PageReleaseQueue::~PageReleaseQueue() {
  flush();
  if (pidfd_ >= 0) ::close(pidfd_);
}

void PageReleaseQueue::release(std::shared_ptr<const MappedFile> file) {
  if (file == nullptr || file->bytes().empty()) return;
  std::vector<std::shared_ptr<const MappedFile>> batch;
  {
    std::lock_guard lock(mutex_);
    pending_bytes_ += file->bytes().size();
    pending_.push_back(std::move(file));
    if (pending_bytes_ < max_pending_bytes_ && pending_.size() < max_pending_mappings_) return;
    batch = take_pending_locked();
  }
  release_now(batch);
}

bool PageReleaseQueue::cancel(const MappedFile* file) {
  std::lock_guard lock(mutex_);
  const auto it =
      std::find_if(pending_.begin(), pending_.end(), [&](const auto& p) { return p.get() == file; });
  if (it == pending_.end()) return false;
  pending_bytes_ -= (*it)->bytes().size();
  pending_.erase(it);
  ++counters_.cancelled;
  return true;
}

std::shared_ptr<const MappedFile> PageReleaseQueue::take(
    std::size_t bytes, const std::function<bool(const std::shared_ptr<const MappedFile>&)>& may_take) {
  static const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const auto pages = [](std::size_t n) { return (n + page - 1) / page; };
  std::lock_guard lock(mutex_);
  auto best = pending_.end();
  for (auto it = pending_.begin(); it != pending_.end(); ++it) {
    const MappedFile& file = **it;
    // Pages past `bytes` would stay populated under the new file, outside
    // what its owner accounts for (read_again would release them: a system
    // call this recycling is meant to save).
    if (!file.is_copy() || file.capacity() < bytes || pages(file.bytes().size()) > pages(bytes)) continue;
    if (best != pending_.end() && (*best)->bytes().size() >= file.bytes().size()) continue;
    if (may_take(*it)) best = it;
  }
  if (best == pending_.end()) return nullptr;
  std::shared_ptr<const MappedFile> file = std::move(*best);
  pending_.erase(best);
  pending_bytes_ -= file->bytes().size();
  ++counters_.taken;
  return file;
}

void PageReleaseQueue::flush() {
  std::vector<std::shared_ptr<const MappedFile>> batch;
  {
    std::lock_guard lock(mutex_);
    if (pending_.empty()) return;
    batch = take_pending_locked();
  }
  release_now(batch);
}

std::vector<std::shared_ptr<const MappedFile>> PageReleaseQueue::take_pending_locked() {
  std::vector<std::shared_ptr<const MappedFile>> batch;
  batch.swap(pending_);
  pending_.reserve(max_pending_mappings_);
  pending_bytes_ = 0;
  return batch;
}

void PageReleaseQueue::release_now(std::vector<std::shared_ptr<const MappedFile>>& batch) {
  bool released_together = false;
  if (batch.size() > 1 && batched_calls_work_.load(std::memory_order_relaxed)) {
    std::vector<iovec> ranges;
    ranges.reserve(batch.size());
    std::size_t total = 0;
    for (const auto& file : batch) {
      // A read-only private mapping has no dirty pages: dropping them loses nothing.
      ranges.push_back({const_cast<char*>(file->bytes().data()), file->bytes().size()});
      total += file->bytes().size();
    }
    const long advised =
        ::syscall(SYS_process_madvise, pidfd_, ranges.data(), ranges.size(), MADV_DONTNEED, 0u);
    if (advised == static_cast<long>(total)) {
      released_together = true;
    } else if (advised < 0 && (errno == EINVAL || errno == ENOSYS || errno == EPERM || errno == EBADF)) {
      // An older kernel (before 6.13 MADV_DONTNEED is for other processes'
      // advice lists only) or a sandbox without the call: one call each
      // from now on.
      batched_calls_work_ = false;
    }
    // Partly done (a range the kernel stopped at): the rest one by one below;
    // releasing a range twice costs little and changes nothing.
  }
  if (!released_together) {
    for (const auto& file : batch) file->release_pages();
  }
  std::lock_guard lock(mutex_);
  counters_.mappings_released += batch.size();
  if (released_together) {
    ++counters_.batches;
  } else {
    counters_.single_calls += batch.size();
  }
}

uint64_t PageReleaseQueue::pending_bytes() const {
  std::lock_guard lock(mutex_);
  return pending_bytes_;
}

PageReleaseCounters PageReleaseQueue::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace outcore
