#include "core/util/shared_memory.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <future>
#include <memory>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Shrinks the object behind every mapping of it, as a careless or hostile
// client could while the server copies.
void truncate_object(const std::string& name, off_t size) {
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  ASSERT_GE(fd, 0) << name;
  ASSERT_EQ(ftruncate(fd, size), 0);
  close(fd);
}

TEST(SharedMemoryObject, WhatTheCreatorWritesTheOpenerCopiesOutAndBack) {
  auto created = SharedMemoryObject::create("test", 1 << 20);
  ASSERT_TRUE(created.ok()) << created.status().message();
  ASSERT_EQ(created->size(), 1u << 20);
  EXPECT_TRUE(created->name().starts_with("/outcore-test-")) << created->name();
  std::iota(reinterpret_cast<uint8_t*>(created->data()) + SharedMemoryObject::kHeaderBytes,
            reinterpret_cast<uint8_t*>(created->data()) + 4096, uint8_t{0});

  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok()) << opened.status().message();
  EXPECT_EQ(opened->size(), created->size());
  std::vector<uint8_t> out(4096);
  ASSERT_TRUE(opened->copy_out(0, out.data(), out.size()).ok());
  EXPECT_EQ(std::memcmp(out.data(), created->data(), out.size()), 0);

  const std::vector<uint8_t> answer(1000, 0xab);
  ASSERT_TRUE(opened->copy_in((1 << 20) - 1000, answer.data(), answer.size()).ok());
  EXPECT_EQ(std::memcmp(created->data() + (1 << 20) - 1000, answer.data(), answer.size()), 0);
}

TEST(SharedMemoryObject, OnlyTheCreatorsTokenPasses) {
  auto created = SharedMemoryObject::create("test", 4096);
  ASSERT_TRUE(created.ok());
  ASSERT_EQ(created->token().size(), SharedMemoryObject::kTokenBytes);
  EXPECT_EQ(std::string(created->data(), SharedMemoryObject::kTokenBytes), created->token());
  auto other = SharedMemoryObject::create("test", 4096);
  ASSERT_TRUE(other.ok());
  EXPECT_NE(other->token(), created->token()) << "tokens are random";

  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  EXPECT_TRUE(opened->token().empty());
  EXPECT_TRUE(opened->check_token(created->token()).ok());
  for (const std::string& wrong : {other->token(), std::string(16, '\0'), created->token().substr(0, 15),
                                   created->token() + "x", std::string()}) {
    const Status status = opened->check_token(wrong);
    EXPECT_EQ(status.code(), StatusCode::kPermissionDenied) << status.message();
    EXPECT_NE(status.message().find(created->name()), std::string::npos) << status.message();
  }
}

TEST(SharedMemoryObject, OpeningMapsOnlyTheBytesAskedFor) {
  auto created = SharedMemoryObject::create("test", 1 << 20);
  ASSERT_TRUE(created.ok());
  auto opened = SharedMemoryObject::open(created->name(), 5000);
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ(opened->size(), 1u << 20);
  EXPECT_EQ(opened->mapped_bytes(), 5000u);
  std::vector<uint8_t> out(8192);
  EXPECT_TRUE(opened->copy_out(0, out.data(), 5000).ok());
  EXPECT_EQ(opened->copy_out(4096, out.data(), 5000).code(), StatusCode::kOutOfRange);
  // Asking for more than the object holds maps the object.
  auto whole = SharedMemoryObject::open(created->name(), 2 << 20);
  ASSERT_TRUE(whole.ok());
  EXPECT_EQ(whole->mapped_bytes(), 1u << 20);
}

TEST(SharedMemoryObject, OrphansOfDeadClientsAreRemovedAndOthersKept) {
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) _exit(0);
  ASSERT_EQ(waitpid(child, nullptr, 0), child);  // `child` is now a dead pid
  const auto make = [](const std::string& name) {
    const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
    EXPECT_GE(fd, 0) << name;
    close(fd);
  };
  const std::string dead = "/outcore-orphantest-" + std::to_string(child) + "-0123456789abcdef";
  const std::string alive = "/outcore-orphantest-" + std::to_string(getpid()) + "-0123456789abcdef";
  const std::string other_kind = "/outcore-otherkind-" + std::to_string(child) + "-0123456789abcdef";
  const std::string not_a_pid = "/outcore-orphantest-12x4-0123456789abcdef";
  for (const std::string& name : {dead, alive, other_kind, not_a_pid}) make(name);
  EXPECT_EQ(SharedMemoryObject::remove_orphans("orphantest"), 1);
  EXPECT_EQ(SharedMemoryObject::open(dead).status().code(), StatusCode::kNotFound);
  for (const std::string& name : {alive, other_kind, not_a_pid}) {
    EXPECT_TRUE(SharedMemoryObject::open(name).ok()) << name;
    shm_unlink(name.c_str());
  }
}

// identify() names the object behind a name without mapping it; an opened
// object keeps that identity and tells when its name was unlinked.
TEST(SharedMemoryObject, IdentityFollowsTheObjectAndUnlinkedIsSeenThroughTheDescriptor) {
  auto created = SharedMemoryObject::create("test", 8192);
  ASSERT_TRUE(created.ok()) << created.status().message();
  const std::string name = created->name();
  auto identity = SharedMemoryObject::identify(name);
  ASSERT_TRUE(identity.ok()) << identity.status().message();
  EXPECT_EQ(identity->size, 8192u);
  EXPECT_EQ(*identity, created->identity());
  auto opened = SharedMemoryObject::open(name);
  ASSERT_TRUE(opened.ok()) << opened.status().message();
  EXPECT_EQ(opened->identity(), *identity);
  EXPECT_FALSE(opened->unlinked());

  truncate_object(name, 4096);  // same object, another size: another identity
  auto shrunk = SharedMemoryObject::identify(name);
  ASSERT_TRUE(shrunk.ok());
  EXPECT_EQ(shrunk->inode, identity->inode);
  EXPECT_NE(*shrunk, *identity);

  created = SharedMemoryObject{};  // the creator unlinks it
  EXPECT_TRUE(opened->unlinked());
  EXPECT_EQ(SharedMemoryObject::identify(name).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(SharedMemoryObject::identify("/elsewhere").status().code(), StatusCode::kInvalidArgument);
}

TEST(SharedMemoryObject, TheCreatorUnlinksItOnDestruction) {
  std::string name;
  {
    auto created = SharedMemoryObject::create("test", 4096);
    ASSERT_TRUE(created.ok());
    name = created->name();
    ASSERT_TRUE(SharedMemoryObject::open(name).ok());
  }
  auto reopened = SharedMemoryObject::open(name);
  ASSERT_FALSE(reopened.ok());
  EXPECT_EQ(reopened.status().code(), StatusCode::kNotFound);
  EXPECT_NE(reopened.status().message().find(name), std::string::npos);
}

TEST(SharedMemoryObject, NamesOutsideThePatternAreRefusedNamingTheProblem) {
  const std::vector<std::string> bad_names = {"",
                                              "/",
                                              "/outcore-",
                                              "outcore-x",
                                              "/other-x",
                                              "/outcore-a/b",
                                              "/outcore-../x",
                                              "/outcore-sp ace",
                                              "/outcore-" + std::string(201, 'a')};
  for (const std::string& bad : bad_names) {
    const Status status = SharedMemoryObject::check_name(bad);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << bad;
    auto opened = SharedMemoryObject::open(bad);
    ASSERT_FALSE(opened.ok()) << bad;
    EXPECT_EQ(opened.status().code(), StatusCode::kInvalidArgument) << bad;
  }
  EXPECT_TRUE(SharedMemoryObject::check_name("/outcore-A.z_0-9").ok());
  EXPECT_TRUE(SharedMemoryObject::check_name("/outcore-" + std::string(200, 'a')).ok());
}

TEST(SharedMemoryObject, AMissingObjectIsNotFound) {
  auto opened = SharedMemoryObject::open("/outcore-test-no-such-object-4f1c2a");
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), StatusCode::kNotFound);
}

// Anyone who can write /dev/shm can put a FIFO or a symbolic link under a
// name the server accepts. Opening a FIFO for reading blocks until a writer
// comes, so the calls run on a thread of their own: should one block, the
// test opens the FIFO's other end to release it and fails.
TEST(SharedMemoryObject, FifosAndSymbolicLinksAreRefusedAtOnceNamingTheObject) {
  const std::string name = "/outcore-test-special-" + std::to_string(getpid());
  const std::string path = "/dev/shm" + name;
  const auto refused_promptly = [&](const char* what, bool fifo, auto call) {
    auto done = std::make_shared<std::promise<Status>>();
    std::future<Status> result = done->get_future();
    std::thread caller([done, call] { done->set_value(call()); });
    const bool prompt = result.wait_for(std::chrono::seconds(5)) == std::future_status::ready;
    if (!prompt && fifo) {
      const int writer = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
      if (writer >= 0) ::close(writer);
    }
    caller.join();
    const Status status = result.get();
    EXPECT_TRUE(prompt) << what << " blocked on " << path;
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << what << ": " << status.to_string();
    EXPECT_NE(status.message().find(name), std::string::npos) << what << ": " << status.message();
  };
  ::unlink(path.c_str());
  ASSERT_EQ(mkfifo(path.c_str(), 0600), 0) << std::strerror(errno);
  refused_promptly("identify(FIFO)", true, [&] { return SharedMemoryObject::identify(name).status(); });
  refused_promptly("open(FIFO)", true, [&] { return SharedMemoryObject::open(name).status(); });
  ::unlink(path.c_str());

  auto target = SharedMemoryObject::create("test", 4096);
  ASSERT_TRUE(target.ok()) << target.status().message();
  ASSERT_EQ(symlink(("/dev/shm" + target->name()).c_str(), path.c_str()), 0) << std::strerror(errno);
  refused_promptly("identify(symlink)", false, [&] { return SharedMemoryObject::identify(name).status(); });
  refused_promptly("open(symlink)", false, [&] { return SharedMemoryObject::open(name).status(); });
  ::unlink(path.c_str());
}

TEST(SharedMemoryObject, RangesOutsideTheObjectAreOutOfRangeAndCopyNothing) {
  auto created = SharedMemoryObject::create("test", 4096);
  ASSERT_TRUE(created.ok());
  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  std::vector<uint8_t> out(8192, 7);
  EXPECT_EQ(opened->copy_out(0, out.data(), 4097).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(opened->copy_out(4097, out.data(), 0).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(opened->copy_out(1, out.data(), 4096).code(), StatusCode::kOutOfRange);
  // An offset near 2^64 must not wrap around into the mapping.
  EXPECT_EQ(opened->copy_out(~std::size_t{0} - 10, out.data(), 100).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(opened->copy_in(4000, out.data(), 200).code(), StatusCode::kOutOfRange);
  EXPECT_TRUE(opened->copy_out(4096, out.data(), 0).ok());
  EXPECT_EQ(out[0], 7);
}

TEST(SharedMemoryObject, AnObjectTruncatedUnderAMappingIsAnErrorNotACrash) {
  auto created = SharedMemoryObject::create("test", 1 << 20);
  ASSERT_TRUE(created.ok());
  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  truncate_object(created->name(), 4096);  // the mapping still spans 1 MiB

  std::vector<uint8_t> buffer(1 << 20);
  const Status read = opened->copy_out(0, buffer.data(), buffer.size());
  EXPECT_EQ(read.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(read.message().find("truncated"), std::string::npos) << read.message();
  EXPECT_NE(read.message().find(created->name()), std::string::npos) << read.message();
  const Status write = opened->copy_in(8192, buffer.data(), 4096);
  EXPECT_EQ(write.code(), StatusCode::kFailedPrecondition);
  // What is still backed copies as before, and the guard is reset.
  EXPECT_TRUE(opened->copy_out(0, buffer.data(), 4096).ok());
  EXPECT_TRUE(opened->copy_in(0, buffer.data(), 4096).ok());
}

TEST(SharedMemoryObject, ThreadsCopyingFromATruncatedObjectEachGetTheError) {
  auto created = SharedMemoryObject::create("test", 1 << 20);
  ASSERT_TRUE(created.ok());
  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  truncate_object(created->name(), 0);
  std::vector<StatusCode> codes(4, StatusCode::kOk);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::vector<uint8_t> buffer(1 << 18);
      for (int round = 0; round < 20; ++round) {
        const Status status = opened->copy_out(std::size_t(t) << 18, buffer.data(), buffer.size());
        if (status.ok() || status.code() != StatusCode::kFailedPrecondition) {
          codes[t] = status.code();
          return;
        }
        codes[t] = status.code();
      }
    });
  }
  for (auto& thread : threads) thread.join();
  for (StatusCode code : codes) EXPECT_EQ(code, StatusCode::kFailedPrecondition);
}

TEST(SharedMemoryObject, AnObjectHoldsAtLeastItsHeader) {
  auto created = SharedMemoryObject::create("test", 0);
  ASSERT_TRUE(created.ok());
  EXPECT_EQ(created->size(), SharedMemoryObject::kHeaderBytes);
  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ(opened->size(), SharedMemoryObject::kHeaderBytes);
  EXPECT_TRUE(opened->check_token(created->token()).ok());
  uint8_t byte = 0;
  EXPECT_TRUE(opened->copy_out(SharedMemoryObject::kHeaderBytes, &byte, 0).ok());
  EXPECT_EQ(opened->copy_out(SharedMemoryObject::kHeaderBytes, &byte, 1).code(), StatusCode::kOutOfRange);
}

TEST(SharedMemoryObject, AnOpenedEmptyObjectMapsNothing) {
  auto created = SharedMemoryObject::create("test", 4096);
  ASSERT_TRUE(created.ok());
  const int fd = shm_open(created->name().c_str(), O_RDWR, 0);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(ftruncate(fd, 0), 0);
  close(fd);
  auto opened = SharedMemoryObject::open(created->name());
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ(opened->size(), 0u);
  EXPECT_EQ(opened->mapped_bytes(), 0u);
  uint8_t byte = 0;
  EXPECT_TRUE(opened->copy_out(0, &byte, 0).ok());
  EXPECT_EQ(opened->copy_out(0, &byte, 1).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(opened->check_token(created->token()).code(), StatusCode::kOutOfRange);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
