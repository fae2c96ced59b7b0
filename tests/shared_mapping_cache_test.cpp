#include "server/shared_mapping_cache.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstring>
#include <string>
#include <vector>

namespace outcore::server {
namespace OUTCORE_UNITY_ID {

std::string header_token(SharedMemoryObject& object) {
  std::string token(SharedMemoryObject::kTokenBytes, '\0');
  EXPECT_TRUE(object.copy_out(0, token.data(), token.size()).ok());
  return token;
}

// A client reusing its object is served by the kept mapping; a larger range
// maps it again; another object under the same name (or the same object at
// another size) is mapped afresh with its own contents.
TEST(SharedMappingCache, ReusesTheMappingOfTheSameObjectAndRemapsWhenItChanged) {
  SharedMappingCache cache;
  auto client = SharedMemoryObject::create("cachetest", 1 << 16);
  ASSERT_TRUE(client.ok()) << client.status().message();
  const std::string name = client->name();

  auto first = cache.open(name, 4096);
  ASSERT_TRUE(first.ok()) << first.status().message();
  EXPECT_EQ((*first)->mapped_bytes(), 4096u);
  EXPECT_EQ(header_token(**first), client->token());
  auto again = cache.open(name, 1024);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->get(), first->get()) << "the same object: the kept mapping";
  EXPECT_EQ(cache.reused(), 1u);
  EXPECT_EQ(cache.mapped(), 1u);

  auto wider = cache.open(name, 1 << 16);
  ASSERT_TRUE(wider.ok());
  EXPECT_NE(wider->get(), first->get()) << "beyond the kept mapping: mapped again";
  EXPECT_EQ((*wider)->mapped_bytes(), 1u << 16);
  EXPECT_EQ(cache.kept(), 1u) << "the narrower mapping of the same name is dropped";
  // An earlier caller's object stays usable after the cache dropped it.
  EXPECT_EQ(header_token(**first), client->token());

  // Another object under the same name: new contents, new mapping.
  ASSERT_EQ(shm_unlink(name.c_str()), 0);
  const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(ftruncate(fd, 1 << 16), 0);
  const std::string other_token(SharedMemoryObject::kTokenBytes, 'x');
  ASSERT_EQ(pwrite(fd, other_token.data(), other_token.size(), 0), static_cast<ssize_t>(other_token.size()));
  auto replaced = cache.open(name, 4096);
  ASSERT_TRUE(replaced.ok()) << replaced.status().message();
  EXPECT_NE(replaced->get(), wider->get());
  EXPECT_EQ(header_token(**replaced), other_token);

  // The same object shrunk: its identity changed, so it is mapped again
  // (and sees the new size).
  ASSERT_EQ(ftruncate(fd, 8192), 0);
  auto shrunk = cache.open(name, 4096);
  ASSERT_TRUE(shrunk.ok());
  EXPECT_NE(shrunk->get(), replaced->get());
  EXPECT_EQ((*shrunk)->size(), 8192u);
  close(fd);
  shm_unlink(name.c_str());
  EXPECT_EQ(cache.open(name, 4096).status().code(), StatusCode::kNotFound);
}

// At most max_objects mappings, least recently used dropped first; mappings
// of objects whose clients unlinked them are dropped at the next open().
TEST(SharedMappingCache, KeepsAtMostItsBoundAndDropsUnlinkedObjects) {
  SharedMappingCache cache(2);
  std::vector<SharedMemoryObject> clients;
  for (int i = 0; i < 3; ++i) {
    auto created = SharedMemoryObject::create("cachetest", 8192);
    ASSERT_TRUE(created.ok()) << created.status().message();
    clients.push_back(std::move(created).value());
  }
  ASSERT_TRUE(cache.open(clients[0].name(), 8192).ok());
  ASSERT_TRUE(cache.open(clients[1].name(), 8192).ok());
  ASSERT_TRUE(cache.open(clients[0].name(), 8192).ok());  // 1 is now the least recent
  ASSERT_TRUE(cache.open(clients[2].name(), 8192).ok());
  EXPECT_EQ(cache.kept(), 2u);
  EXPECT_EQ(cache.mapped(), 3u);
  ASSERT_TRUE(cache.open(clients[0].name(), 8192).ok());
  EXPECT_EQ(cache.mapped(), 3u) << "0 was kept";
  ASSERT_TRUE(cache.open(clients[1].name(), 8192).ok());
  EXPECT_EQ(cache.mapped(), 4u) << "1 was dropped";

  // Client 0 closes its object (unlinking it); any later call drops it.
  clients[0] = SharedMemoryObject{};
  ASSERT_TRUE(cache.open(clients[1].name(), 8192).ok());
  EXPECT_EQ(cache.kept(), 1u);

  SharedMappingCache none(0);
  ASSERT_TRUE(none.open(clients[1].name(), 8192).ok());
  ASSERT_TRUE(none.open(clients[1].name(), 8192).ok());
  EXPECT_EQ(none.kept(), 0u);
  EXPECT_EQ(none.mapped(), 2u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore::server
