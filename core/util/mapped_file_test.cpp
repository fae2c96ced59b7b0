#include "core/util/mapped_file.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <future>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/present_pages.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

constexpr std::size_t kPage = 4096;

using testing::present_pages;

std::size_t pages_of(std::size_t bytes) {
  return (bytes + kPage - 1) / kPage;
}

std::string pattern(std::size_t size, int seed) {
  std::string bytes(size, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i * 7 + seed);
  return bytes;
}

std::string text_of(const MappedFile& file) {
  return {file.bytes().data(), file.bytes().size()};
}

TEST(MappedFile, ReleasedPagesReadTheSameBytesAgain) {
  testing::TempDir dir;
  const std::string path = dir.path() + "/data.bin";
  std::string bytes(3 * 4096 + 17, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i * 7 + 3);
  testing::write_text_file(path, bytes);
  auto mapped = MappedFile::open(path);
  ASSERT_TRUE(mapped.ok()) << mapped.status().to_string();
  ASSERT_EQ(std::string(mapped->bytes().data(), mapped->bytes().size()), bytes);
  mapped->release_pages();
  EXPECT_EQ(std::string(mapped->bytes().data(), mapped->bytes().size()), bytes);
  const Expected<FileIdentity> identity = file_identity(path);
  ASSERT_TRUE(identity.ok());
  EXPECT_EQ(*identity, mapped->identity());
  // An empty file: empty bytes, and releasing them is harmless.
  testing::write_text_file(path + ".empty", "");
  auto empty = MappedFile::open(path + ".empty");
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->bytes().empty());
  empty->release_pages();
  EXPECT_EQ(MappedFile::open(path + ".missing").status().code(), StatusCode::kNotFound);
}

// A copy maps a whole size class but holds (and populates) only its file's
// pages; another file of up to that capacity is read into the same memory,
// and pages the smaller file does not fill leave the RSS.
TEST(MappedFile, ACopyReadsAnotherFileThatFitsItsCapacityIntoTheSameMemory) {
  if (::sysconf(_SC_PAGESIZE) != static_cast<long>(kPage)) GTEST_SKIP() << "page counts assume 4 KiB pages";
  testing::TempDir dir;
  const std::string first = dir.path() + "/first", smaller = dir.path() + "/smaller",
                    larger = dir.path() + "/larger", too_large = dir.path() + "/too_large";
  testing::write_text_file(first, pattern(20 * kPage + 5, 1));
  testing::write_text_file(smaller, pattern(7 * kPage + 100, 2));
  testing::write_text_file(larger, pattern(30 * kPage, 3));
  testing::write_text_file(too_large, pattern(MappedFile::kCopyCapacityStep + 1, 4));

  auto copy = MappedFile::copy(first);
  ASSERT_TRUE(copy.ok()) << copy.status().to_string();
  EXPECT_TRUE(copy->is_copy());
  EXPECT_EQ(copy->capacity(), MappedFile::kCopyCapacityStep);
  EXPECT_EQ(text_of(*copy), pattern(20 * kPage + 5, 1));
  const char* const data = copy->bytes().data();
  EXPECT_EQ(present_pages(data, copy->capacity()), 21u) << "only the file's pages are populated";

  // Pages kept (taken from a release queue): written over; the rest released.
  ASSERT_TRUE(copy->read_again(smaller, /*pages_kept=*/true).ok());
  EXPECT_EQ(copy->bytes().data(), data) << "the same memory";
  EXPECT_EQ(text_of(*copy), pattern(7 * kPage + 100, 2));
  EXPECT_EQ(copy->identity(), *file_identity(smaller));
  EXPECT_EQ(present_pages(data, copy->capacity()), pages_of(7 * kPage + 100))
      << "a smaller file's copy holds no pages past it";

  ASSERT_TRUE(copy->read_again(larger, /*pages_kept=*/true).ok());
  EXPECT_EQ(copy->bytes().data(), data);
  EXPECT_EQ(text_of(*copy), pattern(30 * kPage, 3));
  EXPECT_EQ(present_pages(data, copy->capacity()), 30u);

  // Released pages (the kept copy of an evicted brick): populated again.
  copy->release_pages();
  EXPECT_EQ(present_pages(data, copy->capacity()), 0u);
  ASSERT_TRUE(copy->read_again(first).ok());
  EXPECT_EQ(text_of(*copy), pattern(20 * kPage + 5, 1));
  EXPECT_EQ(present_pages(data, copy->capacity()), 21u);

  const Status status = copy->read_again(too_large);
  EXPECT_EQ(status.code(), StatusCode::kFailedPrecondition) << status.to_string();
  EXPECT_EQ(copy->read_again(dir.path() + "/missing").code(), StatusCode::kNotFound);
  auto mapped = MappedFile::open(first);
  ASSERT_TRUE(mapped.ok());
  EXPECT_FALSE(mapped->is_copy());
  EXPECT_EQ(mapped->capacity(), mapped->bytes().size());
  EXPECT_EQ(mapped->read_again(first).code(), StatusCode::kFailedPrecondition)
      << "file mappings are read only";
}

// A file emptied since its copy was made reads as empty bytes (the copy keeps
// its memory), and a later file is read into that memory again.
TEST(MappedFile, ReadAgainOfAFileThatIsNowEmptyGivesEmptyBytes) {
  testing::TempDir dir;
  const std::string path = dir.path() + "/data";
  testing::write_text_file(path, pattern(3 * kPage, 5));
  auto copy = MappedFile::copy(path);
  ASSERT_TRUE(copy.ok());
  testing::write_text_file(path, "");
  ASSERT_TRUE(copy->read_again(path, /*pages_kept=*/true).ok());
  EXPECT_TRUE(copy->bytes().empty());
  testing::write_text_file(path, pattern(2 * kPage, 6));
  ASSERT_TRUE(copy->read_again(path).ok());
  EXPECT_EQ(text_of(*copy), pattern(2 * kPage, 6));
}

// A FIFO under a subtree file's name (anyone who may write the tier's
// directory can make one) is refused at once, not waited on: open() of a
// FIFO for reading blocks until a writer comes. The calls run on a thread of
// their own; should one block, the test opens the FIFO's other end to
// release it, and fails.
TEST(MappedFile, AFifoIsRefusedAtOnceNamingWhatItIs) {
  testing::TempDir dir;
  const std::string path = dir.path() + "/brick.subtree";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  for (const bool copy : {true, false}) {
    std::packaged_task<Status()> task(
        [&] { return (copy ? MappedFile::copy(path) : MappedFile::open(path)).status(); });
    std::future<Status> result = task.get_future();
    std::thread caller(std::move(task));
    const bool prompt = result.wait_for(std::chrono::seconds(5)) == std::future_status::ready;
    if (!prompt) {
      const int writer = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
      if (writer >= 0) ::close(writer);
    }
    caller.join();
    const Status status = result.get();
    EXPECT_TRUE(prompt) << (copy ? "copy" : "open") << " blocked on the FIFO";
    EXPECT_EQ(status.code(), StatusCode::kIoError) << status.to_string();
    EXPECT_NE(status.message().find(path + " is a FIFO, not a regular file"), std::string::npos)
        << status.message();
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
