#include "core/util/mapped_file.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <future>
#include <string>
#include <thread>

#include "tests/support/test_paths.h"

namespace outcore {
namespace {

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

}  // namespace
}  // namespace outcore
