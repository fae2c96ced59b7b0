#include "core/util/page_release_queue.h"

#include <fcntl.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/present_pages.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

constexpr std::size_t kPage = 4096;

// Pages of `file` present in this process's page tables.
std::size_t mapped_pages(const MappedFile& file) {
  return testing::present_pages(file.bytes().data(), file.bytes().size());
}

// Reads every page (maps them all) and returns the bytes' sum.
uint64_t touch(const MappedFile& file) {
  // Volatile: a caller that ignores the sum still maps the pages.
  const volatile char* bytes = file.bytes().data();
  uint64_t sum = 0;
  for (std::size_t i = 0; i < file.bytes().size(); i += kPage) sum += static_cast<unsigned char>(bytes[i]);
  return sum;
}

class PageReleaseQueueTest : public ::testing::Test {
 protected:
  std::shared_ptr<const MappedFile> make_file(int index, std::size_t pages) {
    const std::string path = dir_.path() + "/f" + std::to_string(index);
    std::string bytes(pages * kPage, '\0');
    for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i * 13 + index);
    testing::write_text_file(path, bytes);
    auto mapped = MappedFile::open(path);
    EXPECT_TRUE(mapped.ok()) << mapped.status().to_string();
    return std::make_shared<const MappedFile>(std::move(mapped).value());
  }
  // A copy (MappedFile::copy) of a new file of `bytes` bytes.
  std::shared_ptr<MappedFile> make_copy(int index, std::size_t bytes) {
    const std::string path = dir_.path() + "/c" + std::to_string(index);
    std::string data(bytes, '\0');
    for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<char>(i * 11 + index);
    testing::write_text_file(path, data);
    auto copied = MappedFile::copy(path);
    EXPECT_TRUE(copied.ok()) << copied.status().to_string();
    return std::make_shared<MappedFile>(std::move(copied).value());
  }

  testing::TempDir dir_;
};

TEST_F(PageReleaseQueueTest, ReleasesABatchWhenFullAndKeepsTheBytes) {
  PageReleaseQueue queue(/*max_pending_bytes=*/1 << 30, /*max_pending_mappings=*/3);
  std::vector<std::shared_ptr<const MappedFile>> files;
  std::vector<uint64_t> sums;
  for (int i = 0; i < 3; ++i) {
    files.push_back(make_file(i, 4));
    sums.push_back(touch(*files.back()));
    ASSERT_EQ(mapped_pages(*files.back()), 4u);
  }
  queue.release(files[0]);
  queue.release(files[1]);
  EXPECT_EQ(queue.pending_bytes(), 8 * kPage);
  EXPECT_EQ(mapped_pages(*files[0]), 4u) << "queued pages stay mapped until the batch is released";
  EXPECT_EQ(queue.counters().mappings_released, 0u);
  queue.release(files[2]);  // the third fills the batch
  EXPECT_EQ(queue.pending_bytes(), 0u);
  const PageReleaseCounters c = queue.counters();
  EXPECT_EQ(c.mappings_released, 3u);
  EXPECT_EQ(c.batches + c.single_calls, c.batches == 1 ? 1u : 3u) << "one batched call, or one call each";
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(mapped_pages(*files[i]), 0u) << "file " << i << ": released pages leave the page tables";
    EXPECT_EQ(touch(*files[i]), sums[i]) << "and read the same bytes again";
  }
}

TEST_F(PageReleaseQueueTest, ByteBoundReleasesEarly) {
  PageReleaseQueue queue(/*max_pending_bytes=*/6 * kPage, /*max_pending_mappings=*/64);
  auto a = make_file(0, 4);
  auto b = make_file(1, 4);
  touch(*a);
  touch(*b);
  queue.release(a);
  EXPECT_EQ(mapped_pages(*a), 4u);
  queue.release(b);  // 8 pages queued > 6
  EXPECT_EQ(mapped_pages(*a), 0u);
  EXPECT_EQ(mapped_pages(*b), 0u);
  EXPECT_EQ(queue.pending_bytes(), 0u);
}

TEST_F(PageReleaseQueueTest, CancelKeepsPagesAndFlushReleasesTheRest) {
  PageReleaseQueue queue(1 << 30, 64);
  auto a = make_file(0, 2);
  auto b = make_file(1, 3);
  touch(*a);
  touch(*b);
  queue.release(a);
  queue.release(b);
  EXPECT_TRUE(queue.cancel(a.get()));
  EXPECT_FALSE(queue.cancel(a.get())) << "no longer queued";
  EXPECT_EQ(queue.pending_bytes(), 3 * kPage);
  queue.flush();
  EXPECT_EQ(mapped_pages(*a), 2u) << "a cancelled mapping keeps its pages";
  EXPECT_EQ(mapped_pages(*b), 0u);
  const PageReleaseCounters c = queue.counters();
  EXPECT_EQ(c.cancelled, 1u);
  EXPECT_EQ(c.mappings_released, 1u);
  EXPECT_EQ(c.single_calls, 1u) << "a batch of one is one madvise";
}

TEST_F(PageReleaseQueueTest, HoldsQueuedMappingsAliveAndReleasesThemOnDestruction) {
  std::weak_ptr<const MappedFile> watched;
  {
    PageReleaseQueue queue(1 << 30, 64);
    auto file = make_file(0, 2);
    touch(*file);
    watched = file;
    queue.release(std::move(file));
    queue.release(nullptr);  // ignored
    EXPECT_FALSE(watched.expired()) << "never released while its range is queued: it could be reused";
  }
  EXPECT_TRUE(watched.expired());
}

TEST_F(PageReleaseQueueTest, ConcurrentReleasesAllHappen) {
  PageReleaseQueue queue(1 << 30, 5);
  constexpr int kThreads = 4;
  constexpr int kPerThread = 12;
  std::vector<std::shared_ptr<const MappedFile>> files;
  for (int i = 0; i < kThreads * kPerThread; ++i) {
    files.push_back(make_file(i, 1));
    touch(*files.back());
  }
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kPerThread; ++i) queue.release(files[t * kPerThread + i]);
    });
  }
  for (auto& thread : threads) thread.join();
  queue.flush();
  EXPECT_EQ(queue.counters().mappings_released, static_cast<uint64_t>(kThreads * kPerThread));
  for (const auto& file : files) EXPECT_EQ(mapped_pages(*file), 0u);
}

// take(): a queued copy that fits the file and has no more pages than it
// fills, the one with most pages, comes out with its pages; file mappings,
// copies too small or with pages to spare, and vetoed ones stay queued.
TEST_F(PageReleaseQueueTest, TakeReturnsTheFullestQueuedCopyThatFits) {
  if (::sysconf(_SC_PAGESIZE) != static_cast<long>(kPage)) GTEST_SKIP() << "page counts assume 4 KiB pages";
  PageReleaseQueue queue(1 << 30, 64);
  auto small = make_copy(0, 2 * kPage);
  auto middle = make_copy(1, 5 * kPage - 10);
  auto big = make_copy(2, 9 * kPage);
  auto mapping = make_file(3, 5);
  touch(*mapping);
  const auto anything = [](const std::shared_ptr<const MappedFile>&) { return true; };
  const auto nothing = [](const std::shared_ptr<const MappedFile>&) { return false; };
  for (const auto& file :
       {std::shared_ptr<const MappedFile>(small), std::shared_ptr<const MappedFile>(middle),
        std::shared_ptr<const MappedFile>(big), mapping}) {
    queue.release(file);
  }
  const uint64_t queued = queue.pending_bytes();

  EXPECT_EQ(queue.take(5 * kPage, nothing), nullptr) << "vetoed";
  EXPECT_EQ(queue.take(kPage, anything), nullptr) << "every copy has more pages than one";
  EXPECT_EQ(queue.take(MappedFile::kCopyCapacityStep + 1, anything), nullptr) << "no copy is that large";
  const std::shared_ptr<const MappedFile> taken = queue.take(6 * kPage, anything);
  EXPECT_EQ(taken, middle) << "5 pages of 6: the fullest that fits (the 5-page file mapping is no copy)";
  EXPECT_EQ(mapped_pages(*taken), 5u) << "taken with its pages";
  EXPECT_EQ(queue.pending_bytes(), queued - middle->bytes().size());
  EXPECT_EQ(queue.counters().taken, 1u);
  EXPECT_FALSE(queue.cancel(middle.get())) << "no longer queued";

  // What the caller then does: read another file into the taken pages.
  const std::string other = dir_.path() + "/other";
  const std::string bytes(6 * kPage - 1, 'x');
  testing::write_text_file(other, bytes);
  ASSERT_TRUE(middle->read_again(other, /*pages_kept=*/true).ok());
  EXPECT_EQ(std::string(middle->bytes().data(), middle->bytes().size()), bytes);

  queue.flush();
  EXPECT_EQ(mapped_pages(*middle), 6u) << "the taken copy is not released with the batch";
  EXPECT_EQ(mapped_pages(*small), 0u);
  EXPECT_EQ(mapped_pages(*big), 0u);
  EXPECT_EQ(queue.counters().mappings_released, 3u);
}

// The caller's veto sees who else holds a copy: the subtree tier's rule (the
// queue and the brick's entry, nobody else) never takes a copy that an accel
// still reads, and takes it once that accel is gone.
TEST_F(PageReleaseQueueTest, TakeLeavesACopyThatSomeoneElseStillHolds) {
  PageReleaseQueue queue(1 << 30, 64);
  auto copy = make_copy(0, 3 * kPage);
  std::shared_ptr<const MappedFile> reader = copy;  // a live accel's lease
  queue.release(copy);                              // the copy's entry keeps `copy`
  const auto only_entry_and_queue = [](const std::shared_ptr<const MappedFile>& file) {
    return file.use_count() == 2;
  };
  EXPECT_EQ(queue.take(3 * kPage, only_entry_and_queue), nullptr);
  reader.reset();
  EXPECT_EQ(queue.take(3 * kPage, only_entry_and_queue), copy);
  EXPECT_EQ(queue.pending_bytes(), 0u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
