// StreamPipeline (server/stream_pipeline.h) on its own, with a reply stream
// whose writes the test holds: replies keep their order, tracing goes on
// while a reply is being written (chunks larger than the group limit
// included), the replies waiting for the writer stay bounded, and a failed
// write stops the pipeline.
#include "server/stream_pipeline.h"

#include <gtest/gtest.h>

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <vector>

namespace outcore::server {
namespace OUTCORE_UNITY_ID {

using Response = v1::IntersectResponse;

// Records each reply's sequence; a write waits while the test holds the gate
// and fails from `fail_from` on.
class HeldStream {
 public:
  bool Write(const Response& reply) {
    std::unique_lock lock(mutex_);
    ++started_;
    changed_.notify_all();
    changed_.wait(lock, [&] { return open_; });
    written_.push_back(reply.sequence());
    return written_.size() <= fail_from_;
  }
  void hold() {
    std::lock_guard lock(mutex_);
    open_ = false;
  }
  void release() {
    std::lock_guard lock(mutex_);
    open_ = true;
    changed_.notify_all();
  }
  void wait_for_started(std::size_t n) {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return started_ >= n; });
  }
  void fail_from(std::size_t n) { fail_from_ = n; }
  std::vector<uint64_t> written() {
    std::lock_guard lock(mutex_);
    return written_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  bool open_ = true;
  std::size_t started_ = 0;
  std::size_t fail_from_ = ~std::size_t{0};
  std::vector<uint64_t> written_;
};

using Pipeline = StreamPipeline<Response, HeldStream>;

std::unique_ptr<StreamChunk> chunk_of(Pipeline& pipeline, uint64_t sequence, std::size_t rays,
                                      std::vector<Ray>& storage) {
  std::unique_ptr<StreamChunk> chunk = pipeline.spare_chunk();
  chunk->request.set_sequence(sequence);
  chunk->rays = std::span<const Ray>(storage.data(), rays);
  return chunk;
}

// A tracer that answers each group with one reply per chunk (its sequence)
// and counts the groups it has posted.
void run_tracer(Pipeline& pipeline, std::atomic<int>& posted) {
  Pipeline::Chunks group;
  Pipeline::Replies replies;
  while (pipeline.take_group(group)) {
    if (!pipeline.acquire_replies(group.size(), replies)) break;
    for (std::size_t i = 0; i < group.size(); ++i) {
      replies[i]->set_sequence(group[i]->request.sequence());
      replies[i]->set_ray_count(group[i]->rays.size());
    }
    pipeline.post_replies(replies, 0.0);
    pipeline.recycle(group);
    ++posted;
  }
}

TEST(StreamPipeline, TracingGoesOnWhileAReplyIsWrittenAndWaitingRepliesStayBounded) {
  HeldStream stream;
  std::vector<Ray> storage(1000);
  // Chunks of 1,000 rays against a group limit of 100: each chunk is a group
  // of its own and each reply is over the limit.
  Pipeline pipeline(&stream, /*max_group_rays=*/100);
  std::atomic<int> posted{0};
  pipeline.start([&] { run_tracer(pipeline, posted); });
  stream.hold();
  ASSERT_TRUE(pipeline.push(chunk_of(pipeline, 0, 1000, storage)));
  stream.wait_for_started(1);  // reply 0 is being written, and held there
  ASSERT_TRUE(pipeline.push(chunk_of(pipeline, 1, 1000, storage)));
  ASSERT_TRUE(pipeline.push(chunk_of(pipeline, 2, 1000, storage)));
  // Replies 1 and 2 are traced while reply 0 is still being written...
  for (int spins = 0; posted.load() < 3 && spins < 2000; ++spins)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(posted.load(), 3) << "tracing waited for the writer";
  // ...but a fourth waits: two replies queued behind the one being written
  // is the bound.
  ASSERT_TRUE(pipeline.push(chunk_of(pipeline, 3, 1000, storage)));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(posted.load(), 3) << "replies waiting for the writer are not bounded";
  stream.release();
  ASSERT_TRUE(pipeline.push(chunk_of(pipeline, 4, 10, storage)));
  EXPECT_TRUE(pipeline.close_and_wait());
  EXPECT_EQ(posted.load(), 5);
  EXPECT_EQ(stream.written(), (std::vector<uint64_t>{0, 1, 2, 3, 4}));
}

TEST(StreamPipeline, SmallChunksAreGroupedUpToTheLimitAndAnsweredInOrder) {
  HeldStream stream;
  std::vector<Ray> storage(40);
  Pipeline pipeline(&stream, /*max_group_rays=*/100);
  std::atomic<int> posted{0};
  // Two chunks (80 rays) queued before the tracer starts: its first group
  // takes both (a third would pass the limit). push waits while the limit
  // is queued, so no more can be queued before it starts.
  for (uint64_t s = 0; s < 2; ++s) ASSERT_TRUE(pipeline.push(chunk_of(pipeline, s, 40, storage)));
  pipeline.start([&] { run_tracer(pipeline, posted); });
  for (uint64_t s = 2; s < 10; ++s) ASSERT_TRUE(pipeline.push(chunk_of(pipeline, s, 40, storage)));
  EXPECT_TRUE(pipeline.close_and_wait());
  EXPECT_EQ(stream.written(), (std::vector<uint64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
  EXPECT_LT(posted.load(), 10) << "queued chunks were not traced together";
}

TEST(StreamPipeline, AFailedWriteStopsThePipelineAndTheHandlersPushes) {
  HeldStream stream;
  stream.fail_from(1);  // the client goes away after the first reply
  std::vector<Ray> storage(500);
  Pipeline pipeline(&stream, /*max_group_rays=*/100);
  std::atomic<int> posted{0};
  pipeline.start([&] { run_tracer(pipeline, posted); });
  bool pushed = true;
  for (uint64_t s = 0; s < 50 && pushed; ++s) pushed = pipeline.push(chunk_of(pipeline, s, 500, storage));
  EXPECT_FALSE(pushed) << "the handler kept reading after the client went away";
  EXPECT_FALSE(pipeline.close_and_wait());
  EXPECT_TRUE(pipeline.write_failed());
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore::server
