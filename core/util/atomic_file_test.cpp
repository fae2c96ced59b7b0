#include "core/util/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;

std::vector<std::string> names_in(const std::string& directory) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(directory))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string contents(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

TEST(AtomicFile, CommitReplacesTheTargetAndLeavesNoTemporary) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/data.bin";
  testing::write_text_file(target, "old");
  AtomicFile file;
  ASSERT_TRUE(file.create(target).ok());
  EXPECT_TRUE(fs::exists(file.temp_path()));
  EXPECT_EQ(fs::path(file.temp_path()).parent_path(), fs::path(dir.path())) << "beside the target";
  EXPECT_TRUE(fs::path(file.temp_path()).filename().string().starts_with(".data.bin.tmp-"));
  ASSERT_TRUE(file.write("new ").ok());
  ASSERT_TRUE(file.write("bytes").ok());
  EXPECT_EQ(contents(target), "old") << "the target is untouched until the commit";
  ASSERT_TRUE(file.commit().ok());
  EXPECT_EQ(contents(target), "new bytes");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"data.bin"});
}

TEST(AtomicFile, AFailedCommitRemovesTheTemporaryAndLeavesTheTarget) {
  testing::TempDir dir;
  // A non-empty directory at the target: the rename fails.
  const std::string target = dir.path() + "/occupied";
  fs::create_directories(target + "/inside");
  AtomicFile file;
  ASSERT_TRUE(file.create(target).ok());
  ASSERT_TRUE(file.write("bytes").ok());
  const std::string temp = file.temp_path();
  const Status committed = file.commit();
  EXPECT_FALSE(committed.ok());
  EXPECT_NE(committed.message().find("cannot rename " + temp + " to " + target), std::string::npos)
      << committed.message();
  EXPECT_FALSE(fs::exists(temp));
  EXPECT_TRUE(fs::is_directory(target + "/inside"));
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"occupied"});
}

TEST(AtomicFile, AnAbandonedFileRemovesItsTemporary) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/data.bin";
  testing::write_text_file(target, "old");
  {
    AtomicFile file;
    ASSERT_TRUE(file.create(target).ok());
    ASSERT_TRUE(file.write("partial").ok());
  }
  EXPECT_EQ(contents(target), "old");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"data.bin"});
}

TEST(AtomicFile, PreparedTemporaryIsWrittenByTheCallerAndRenamed) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/brick-1";
  AtomicFile file;
  file.prepare(target);
  EXPECT_FALSE(fs::exists(file.temp_path())) << "prepare() creates nothing";
  testing::write_text_file(file.temp_path(), "written elsewhere");
  ASSERT_TRUE(file.commit().ok());
  EXPECT_EQ(contents(target), "written elsewhere");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"brick-1"});

  AtomicFile abandoned;
  abandoned.prepare(target);
  testing::write_text_file(abandoned.temp_path(), "never committed");
  abandoned.discard();
  EXPECT_EQ(contents(target), "written elsewhere");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"brick-1"});
}

TEST(AtomicFile, CreatingBesideAMissingDirectoryFailsNamingTheTarget) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/missing/data.bin";
  AtomicFile file;
  const Status created = file.create(target);
  EXPECT_FALSE(created.ok());
  EXPECT_NE(created.message().find("cannot create a temporary file beside " + target), std::string::npos)
      << created.message();
  EXPECT_FALSE(file.commit().ok());
}

TEST(AtomicFile, ModeIsSetDespiteTheUmask) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/shared.bin";
  const mode_t old_umask = ::umask(0077);
  AtomicWriteOptions options;
  options.mode = 0644;
  options.sync = true;
  const std::string_view parts[] = {"a", "b"};
  const Status written = write_file_atomically(target, parts, options);
  ::umask(old_umask);
  ASSERT_TRUE(written.ok()) << written.to_string();
  EXPECT_EQ(fs::status(target).permissions() & fs::perms::all,
            fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read | fs::perms::others_read);
  EXPECT_EQ(contents(target), "ab");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"shared.bin"});
}

TEST(AtomicDirectory, CommitReplacesAnExistingTargetAndLeavesNothingBeside) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/store";
  fs::create_directories(target);
  testing::write_text_file(target + "/old.txt", "old");
  AtomicDirectory store;
  ASSERT_TRUE(store.create(target).ok());
  EXPECT_TRUE(fs::path(store.path()).filename().string().starts_with("store.partial-"));
  testing::write_text_file(store.path() + "/new.txt", "new");
  ASSERT_TRUE(sync_file(store.path() + "/new.txt").ok());
  ASSERT_TRUE(store.commit(/*sync=*/true, "store").ok());
  EXPECT_EQ(names_in(target), std::vector<std::string>{"new.txt"});
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"store"}) << "no partial or displaced directory";
}

TEST(AtomicDirectory, AnUncommittedDirectoryIsRemovedAndTheTargetKept) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/store";
  fs::create_directories(target);
  testing::write_text_file(target + "/old.txt", "old");
  {
    AtomicDirectory store;
    ASSERT_TRUE(store.create(target).ok());
    testing::write_text_file(store.path() + "/new.txt", "new");
  }
  EXPECT_EQ(names_in(target), std::vector<std::string>{"old.txt"});
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"store"});
}

TEST(AtomicDirectory, NewDirectoryFollowsTheUmask) {
  testing::TempDir dir;
  const std::string target = dir.path() + "/store";
  const mode_t old_umask = ::umask(0022);
  AtomicDirectory store;
  const Status created = store.create(target);
  ::umask(old_umask);
  ASSERT_TRUE(created.ok());
  ASSERT_TRUE(store.commit(/*sync=*/false, "store").ok());
  EXPECT_EQ(fs::status(target).permissions() & fs::perms::all,
            fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec | fs::perms::others_read |
                fs::perms::others_exec);
}

TEST(SyncFile, MissingFileFailsNamingIt) {
  const Status synced = sync_file("/nonexistent/outcore/file");
  EXPECT_FALSE(synced.ok());
  EXPECT_NE(synced.message().find("cannot sync /nonexistent/outcore/file"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
