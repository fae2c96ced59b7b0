#include "core/util/mapped_file.h"

#include <gtest/gtest.h>

#include <string>

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

}  // namespace
}  // namespace outcore
