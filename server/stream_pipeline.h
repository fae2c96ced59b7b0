// StreamPipeline: the three stages of one IntersectStream/OccludedStream call,
// each on its own thread, so that the wire and the engine overlap:
//
//   the handler thread   reads and checks chunk k+2 (push),
//   a tracer thread      traces the chunks that have arrived (take_group),
//   a writer thread      writes the replies to chunks k and before.
//
// Without it the sync handler would trace, then block in Write until HTTP/2
// flow control let the whole reply out, then wait for the next chunk, with the
// engine idle meanwhile. And while the engine is busy, the chunks that arrive
// queue up; the tracer takes them all (up to max_group_rays) into one engine
// call, because the engine is much cheaper per ray on big batches
// (docs/BENCHMARKS_HISTORY.md, "--stream-group-rays"). A fast engine thus
// gets small batches and full overlap, a busy one big batches.
//
// Only the handler thread ever calls Read: the handler returns (ending the
// call) only once the tracer and the writer are done, and a pending Read on
// another thread would outlive the call. gRPC allows one Read and one Write in
// flight on a stream at a time from different threads.
//
// Gathering (gather_wait > 0; the server's default when its cache cannot hold
// the scene): the tracer does not start on the first chunk that arrives but
// waits for the group to fill (max_group_rays rays queued, or the input
// closed), as long as chunks keep coming at most gather_wait apart. Under a
// tight budget every engine call rebuilds most bricks it touches, so a
// stream traced chunk by chunk costs a pass over the scene per call; gathered,
// one. A client that waits for each reply before sending the next chunk gets
// it gather_wait late, never stuck.
//
// Memory is bounded: push waits while max_group_rays rays are queued
// untraced, and acquire_reply waits while more than max_group_rays rays of
// replies are unwritten and two are still queued for the writer: a reply
// being written and one queued while the next group is traced (without that
// allowance, a chunk larger than max_group_rays would make tracing wait for
// each write).
//
// Thread-safety: push/spare_chunk/close_and_wait are for the handler thread,
// take_group/recycle/acquire_reply/post_replies/fail for the tracer thread
// (run_tracer); the writer thread is internal.
#pragma once

#include <grpcpp/support/sync_stream.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "core/dynamic/dynamic_snapshot.h"
#include "core/ray/ray_types.h"
#include "outcore/v1/scene_query.pb.h"
#include "server/ray_batch.h"

namespace outcore::server {

// One checked request chunk of a stream; reused for later chunks (its
// buffers keep their capacity).
struct StreamChunk {
  v1::QueryRequest request;
  std::vector<Ray> widened;   // F32X6 rays (or misaligned F32X8) widened here
  std::span<const Ray> rays;  // the chunk's rays, in request or in widened
  BatchPosition position;
  std::shared_ptr<const DynamicSnapshot> dynamic;  // the stream's version of the dynamic layer
};

// Figures of one stream for the debug log.
struct StreamTimes {
  double reading = 0;           // handler inside Read
  double waiting_to_queue = 0;  // handler waiting for the tracer (backpressure)
  double tracing = 0;           // tracer answering groups
  double waiting_to_reply = 0;  // tracer waiting for the writer (backpressure)
  double writing = 0;           // writer inside Write
  uint64_t groups = 0;          // engine calls
};

// Stream: what replies are written to (gRPC's server stream; the pipeline
// only calls its Write, so tests can give it a stream of their own).
template <class Response, class Stream = grpc::ServerReaderWriter<Response, v1::QueryRequest>>
class StreamPipeline {
 public:
  using Chunks = std::vector<std::unique_ptr<StreamChunk>>;
  using Replies = std::vector<std::unique_ptr<Response>>;

  StreamPipeline(Stream* stream, uint64_t max_group_rays,
                 std::chrono::milliseconds gather_wait = std::chrono::milliseconds(0))
      : stream_(stream), max_group_rays_(max_group_rays), gather_wait_(gather_wait) {}
  ~StreamPipeline() { close_and_wait(); }
  StreamPipeline(const StreamPipeline&) = delete;
  StreamPipeline& operator=(const StreamPipeline&) = delete;

  // Starts the writer and a tracer thread running `trace`, which calls
  // take_group until it returns false, answers each group, and calls fail()
  // on an error.
  void start(std::function<void()> trace) {
    writer_ = std::thread([this] { write_loop(); });
    tracer_ = std::thread(std::move(trace));
  }

  // A chunk to read the next request into (a recycled one when available).
  std::unique_ptr<StreamChunk> spare_chunk() {
    std::lock_guard lock(mutex_);
    if (spare_.empty()) return std::make_unique<StreamChunk>();
    std::unique_ptr<StreamChunk> chunk = std::move(spare_.back());
    spare_.pop_back();
    return chunk;
  }

  // Queues a checked chunk for the tracer; false once the tracer or the writer
  // failed (the handler then stops reading).
  bool push(std::unique_ptr<StreamChunk> chunk) {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return failed_ || queued_rays_ < max_group_rays_; });
    times_.waiting_to_queue += seconds_since(start);
    if (failed_) return false;
    queued_rays_ += chunk->rays.size();
    queued_.push_back(std::move(chunk));
    changed_.notify_all();
    return true;
  }

  // Tracer: waits for chunks and moves the queued ones into `group` (at least
  // one, then more while they share the first one's query flags and stay
  // within max_group_rays); false once input is closed and all are taken.
  bool take_group(Chunks& group) {
    group.clear();
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return input_closed_ || failed_ || !queued_.empty(); });
    if (gather_wait_.count() > 0) {
      const auto full = [&] { return input_closed_ || failed_ || queued_rays_ >= max_group_rays_; };
      while (!full()) {
        const std::size_t seen = queued_.size();
        if (!changed_.wait_for(lock, gather_wait_, [&] { return full() || queued_.size() != seen; })) break;
      }
    }
    if (failed_ || queued_.empty()) return false;
    uint64_t rays = 0;
    const v1::QueryRequest& first = queued_.front()->request;
    while (!queued_.empty()) {
      const StreamChunk& next = *queued_.front();
      if (!group.empty() &&
          (rays + next.rays.size() > max_group_rays_ || next.request.strict() != first.strict() ||
           next.request.no_reorder() != first.no_reorder())) {
        break;
      }
      rays += next.rays.size();
      queued_rays_ -= next.rays.size();
      group.push_back(std::move(queued_.front()));
      queued_.pop_front();
    }
    changed_.notify_all();
    return true;
  }

  // Tracer: gives traced chunks back for reuse.
  void recycle(Chunks& group) {
    std::lock_guard lock(mutex_);
    for (auto& chunk : group) spare_.push_back(std::move(chunk));
    group.clear();
  }

  // Tracer: `count` cleared replies to fill (recycled ones when available),
  // waiting while more than max_group_rays rays of replies await the writer;
  // false once a write failed.
  bool acquire_replies(size_t count, Replies& replies) {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock lock(mutex_);
    changed_.wait(lock,
                  [&] { return failed_ || unwritten_rays_ <= max_group_rays_ || to_write_.size() < 2; });
    times_.waiting_to_reply += seconds_since(start);
    if (failed_) return false;
    replies.clear();
    while (replies.size() < count) {
      if (spare_replies_.empty()) {
        replies.push_back(std::make_unique<Response>());
      } else {
        replies.push_back(std::move(spare_replies_.back()));
        spare_replies_.pop_back();
        replies.back()->Clear();  // keeps the payload's capacity
      }
    }
    return true;
  }

  // Tracer: queues filled replies for writing, in order.
  void post_replies(Replies& replies, double seconds_tracing) {
    std::lock_guard lock(mutex_);
    times_.tracing += seconds_tracing;
    ++times_.groups;
    for (auto& reply : replies) {
      unwritten_rays_ += reply->ray_count();
      to_write_.push_back(std::move(reply));
    }
    replies.clear();
    changed_.notify_all();
  }

  // Tracer: stops the pipeline (the handler stops reading, unwritten replies
  // are still written).
  void fail() {
    std::lock_guard lock(mutex_);
    failed_ = true;
    changed_.notify_all();
  }

  // Handler: no more chunks; waits for the tracer to answer the queued ones
  // and the writer to write every reply. True when nothing failed. Idempotent.
  bool close_and_wait() {
    {
      std::lock_guard lock(mutex_);
      input_closed_ = true;
      changed_.notify_all();
    }
    if (tracer_.joinable()) tracer_.join();
    {
      std::lock_guard lock(mutex_);
      tracer_done_ = true;
      changed_.notify_all();
    }
    if (writer_.joinable()) writer_.join();
    return !failed_ && !write_failed_;
  }

  bool write_failed() const { return write_failed_; }
  const StreamTimes& times() const { return times_; }
  void add_reading_time(double seconds) { times_.reading += seconds; }

 private:
  static double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  void write_loop() {
    std::unique_lock lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return tracer_done_ || !to_write_.empty(); });
      if (to_write_.empty()) return;  // the tracer is done and all is written
      std::unique_ptr<Response> reply = std::move(to_write_.front());
      to_write_.pop_front();
      const bool skip = write_failed_;
      lock.unlock();
      const auto start = std::chrono::steady_clock::now();
      const bool written = !skip && stream_->Write(*reply);
      const double seconds = seconds_since(start);
      lock.lock();
      times_.writing += seconds;
      unwritten_rays_ -= reply->ray_count();
      spare_replies_.push_back(std::move(reply));
      if (!written) write_failed_ = failed_ = true;
      changed_.notify_all();
    }
  }

  Stream* stream_;
  const uint64_t max_group_rays_;
  const std::chrono::milliseconds gather_wait_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::unique_ptr<StreamChunk>> queued_;  // checked, untraced, in order
  uint64_t queued_rays_ = 0;
  std::vector<std::unique_ptr<StreamChunk>> spare_;
  std::deque<std::unique_ptr<Response>> to_write_;  // in order
  uint64_t unwritten_rays_ = 0;
  std::vector<std::unique_ptr<Response>> spare_replies_;
  bool input_closed_ = false;
  bool tracer_done_ = false;
  bool failed_ = false;        // the tracer or the writer failed
  bool write_failed_ = false;  // a Write returned false (the client went away)
  StreamTimes times_;
  std::thread tracer_;
  std::thread writer_;
};

}  // namespace outcore::server
