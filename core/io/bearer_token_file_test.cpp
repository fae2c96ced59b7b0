// The bearer token file (serve/query --auth-token-file): trailing newlines
// dropped, bad files named, and the comparison exact.
#include "core/io/bearer_token_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace outcore {
namespace OUTCORE_UNITY_ID {

class BearerTokenFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("outcore-token-test-" + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  std::filesystem::path dir_;
};

TEST_F(BearerTokenFile, ReadsTheTokenWithoutTrailingNewlinesAndSpaces) {
  auto token = read_bearer_token_file(write("t", "abc.DEF-123_=\r\n \n"));
  ASSERT_TRUE(token.ok()) << token.status().message();
  EXPECT_EQ(*token, "abc.DEF-123_=");
}

TEST_F(BearerTokenFile, RefusesEmptySpacedLongAndMissingFilesNamingThem) {
  const std::string empty = write("empty", "\n\n");
  auto result = read_bearer_token_file(empty);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find(empty), std::string::npos);
  EXPECT_NE(result.status().message().find("empty"), std::string::npos);

  result = read_bearer_token_file(write("spaced", "two words\n"));
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("byte 3"), std::string::npos) << result.status().message();

  result = read_bearer_token_file(write("control", std::string("a\0b", 3)));
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("byte 1"), std::string::npos);

  result = read_bearer_token_file(write("long", std::string(kMaxBearerTokenBytes + 1, 'x')));
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find("at most"), std::string::npos);
  EXPECT_TRUE(read_bearer_token_file(write("longest", std::string(kMaxBearerTokenBytes, 'x'))).ok());

  const std::string missing = (dir_ / "missing").string();
  result = read_bearer_token_file(missing);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kNotFound);
  EXPECT_NE(result.status().message().find(missing), std::string::npos);
}

TEST(BearerTokens, CompareExactly) {
  EXPECT_TRUE(tokens_equal("secret", "secret"));
  EXPECT_FALSE(tokens_equal("secreT", "secret"));
  EXPECT_FALSE(tokens_equal("Secret", "secret"));
  EXPECT_FALSE(tokens_equal("secret", "secret1"));
  EXPECT_FALSE(tokens_equal("", "secret"));
  EXPECT_TRUE(tokens_equal("", ""));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
