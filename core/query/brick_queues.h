// BrickQueues: the queued strategy's queues: per brick the rays waiting to
// be traced there, the bricks with a non-empty queue, and, for trace-ahead,
// per brick the rays that have it further on in their window.
//
// Thread-safety: written on one thread, between parallel phases.
#pragma once

#include <cstdint>
#include <vector>

#include "core/query/batch_scratch.h"
#include "core/query/ray_walk.h"

namespace outcore {

class BrickQueues {
 public:
  // Over the scratch's queue buffers (kept across batches); with
  // `list_upcoming` each queued ray's later window entries are listed too.
  BrickQueues(BatchScratch& scratch, uint32_t brick_count, bool list_upcoming)
      : queues_(scratch.queues),
        upcoming_(scratch.upcoming),
        progress_(scratch.progress.data()),
        is_waiting_(brick_count, 0),
        list_upcoming_(list_upcoming) {
    if (queues_.size() < brick_count) queues_.resize(brick_count);
    for (auto& queue : queues_) queue.clear();  // a failed batch may have left rays
    if (list_upcoming_) {
      if (upcoming_.size() < brick_count) upcoming_.resize(brick_count);
      for (auto& list : upcoming_) list.clear();
    }
  }

  void enqueue(uint32_t brick, uint32_t ray) {
    queues_[brick].push_back(ray);
    if (!is_waiting_[brick]) {
      is_waiting_[brick] = 1;
      waiting_.push_back(brick);
    }
    if (list_upcoming_) list_upcoming(ray);
  }

  // Bricks with a non-empty queue (in no particular order).
  std::vector<uint32_t>& waiting() { return waiting_; }
  std::size_t queue_size(uint32_t brick) const { return queues_[brick].size(); }
  // Moves the brick's queue into `into` (both keep their buffers); the brick
  // is no longer waiting (the caller takes it out of waiting()).
  void take(uint32_t brick, std::vector<uint32_t>& into) {
    is_waiting_[brick] = 0;
    into.swap(queues_[brick]);
    queues_[brick].clear();
  }
  // Rays with `brick` further on in their window (trace-ahead candidates).
  std::vector<uint32_t>& upcoming(uint32_t brick) { return upcoming_[brick]; }

 private:
  void list_upcoming(uint32_t ray) {
    RayProgress& p = progress_[ray];
    for (uint8_t k = p.next; k < p.count; ++k) {
      if (p.listed & (1u << k)) continue;
      p.listed |= static_cast<uint8_t>(1u << k);
      upcoming_[p.window[k].brick].push_back(ray);
    }
  }

  std::vector<std::vector<uint32_t>>& queues_;
  std::vector<std::vector<uint32_t>>& upcoming_;
  RayProgress* progress_;
  std::vector<uint32_t> waiting_;
  std::vector<uint8_t> is_waiting_;
  bool list_upcoming_;
};

}  // namespace outcore
