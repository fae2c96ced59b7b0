// The C++ client's cache-affinity routing (client/cpp/replica_ring.h,
// replica_router.h): the hash, keys, brick places, walks and assignment
// equal the Python client's (outcore/_routing.py) on fixed vectors, so both
// send the same rays and bricks to the same replicas; and three real
// `outcore serve` replicas under a small budget answer a batch routed by
// brick or by ray bitwise like one server, also when one of them is killed
// before the batch.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "client/cpp/replica_ring.h"
#include "client/cpp/replica_router.h"
#include "tests/support/packed_scene.h"
#include "tests/support/server_process.h"
#include "tests/support/test_rays.h"

namespace outcore::client {
namespace OUTCORE_UNITY_ID {

std::vector<Ray> vector_rays() {
  const float rows[6][6] = {{0.3f, 5, 0.3f, 0, -1, 0},      {0.3f, -5, 0.3f, 0, 1, 0},
                            {0.9f, 5, 0.9f, 0, -1, 0},      {-5, 5, 5, -1, 0, 0},
                            {0.01f, 0.01f, 0.01f, 1, 0, 0}, {0.5f, 0.05f, -3, 0.1f, 0, 1}};
  std::vector<Ray> rays;
  for (const auto& r : rows) rays.push_back(Ray{{r[0], r[1], r[2]}, {r[3], r[4], r[5]}});
  return rays;
}

TEST(ReplicaRing, HashKeysWalksAndAssignmentMatchThePythonClient) {
  // Values printed by outcore._routing for the same inputs.
  EXPECT_EQ(ring_hash("a:1#0"), 0xdd7a34b63194174dull);
  EXPECT_EQ(ring_hash("127.0.0.1:50051#3"), 0x33629d84c96846faull);
  EXPECT_EQ(ring_hash("miss:0"), 0xc08716614b83a1c4ull);
  EXPECT_EQ(ring_hash(""), 0xf52a15e9a9b5e89bull);
  const std::vector<uint64_t> keys = route_keys(vector_rays(), {0, 0, 0}, {1, 0.1f, 1}, 8);
  const std::vector<uint64_t> expected = {0x1440000000000000ull, 0x1440000000000000ull,
                                          0xb6c0000000000000ull, 0xc08716614b83a1c4ull,
                                          0x40000000000000ull,   0x2440000000000000ull};
  EXPECT_EQ(keys, expected);
  const ReplicaRing ring({"c:3", "a:1", "b:2"});
  ASSERT_EQ(ring.replicas(), (std::vector<std::string>{"a:1", "b:2", "c:3"}));
  const std::vector<std::vector<uint32_t>> walks = {{2, 0, 1}, {2, 0, 1}, {0, 2, 1},
                                                    {0, 2, 1}, {2, 0, 1}, {1, 2, 0}};
  for (std::size_t i = 0; i < keys.size(); ++i) EXPECT_EQ(ring.walk(keys[i]), walks[i]) << i;
  const std::map<uint64_t, uint64_t> counts = {
      {keys[0], 2}, {keys[2], 3}, {keys[3], 4}, {keys[4], 5}, {keys[5], 6}};
  const std::map<uint64_t, uint32_t> owner = ring.assign(counts);
  EXPECT_EQ(owner.at(keys[5]), 1u);
  EXPECT_EQ(owner.at(keys[4]), 2u);
  EXPECT_EQ(owner.at(keys[3]), 0u);
  EXPECT_EQ(owner.at(keys[2]), 0u);
  EXPECT_EQ(owner.at(keys[0]), 2u);
}

TEST(ReplicaRing, BrickPlacesAndTheirAssignmentMatchThePythonClient) {
  // Values printed by outcore._routing.brick_positions and
  // HashRing(..., BRICK_VIRTUAL_NODES).assign(..., BRICK_LOAD_FACTOR).
  const Vec3f lo{0, 0, 0}, hi{1, 0.1f, 1};
  const std::vector<uint64_t> places = {brick_ring_position(0, {0, 0, 0}, {1, 0.1f, 1}, lo, hi),
                                        brick_ring_position(1, {0.25f, 0, 0.5f}, {0.5f, 0.05f, 1}, lo, hi),
                                        brick_ring_position(2, {-1, -1, -1}, {0, 0, 0}, lo, hi)};
  EXPECT_EQ(places, (std::vector<uint64_t>{0xe000054985587993ull, 0x9c80023b73f1bdacull, 0x357e04cec2eull}));
  const ReplicaRing ring({"c:3", "a:1", "b:2"}, kBrickVirtualNodes);
  const std::map<uint64_t, uint32_t> owner =
      ring.assign({{places[0], 5}, {places[1], 3}, {places[2], 4}}, kBrickLoadFactor);
  EXPECT_EQ(owner.at(places[0]), 2u);
  EXPECT_EQ(owner.at(places[1]), 1u);
  EXPECT_EQ(owner.at(places[2]), 0u);
}

TEST(ReplicaRing, ReplicaListsAreCommaListsWithoutAScheme) {
  EXPECT_EQ(*replica_list("a:1,b:2"), (std::vector<std::string>{"a:1", "b:2"}));
  EXPECT_TRUE(replica_list("127.0.0.1:50051")->empty());
  EXPECT_TRUE(replica_list("ipv4:127.0.0.1:1,127.0.0.1:2")->empty());  // one gRPC target
  EXPECT_TRUE(replica_list("dns:///127.0.0.1:50051")->empty());        // resolves to one server
  const auto unknown = replica_list("dns:///no-such-host.invalid:50051");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("no-such-host.invalid"), std::string::npos);
}

class ReplicaRouterTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = testing::pack_test_scene({"gen:city?copies=100"}, 8192).release();
    rays_ = testing::make_test_rays(scene_->bounds, 60000, 30);
  }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  static std::vector<std::unique_ptr<testing::ServerProcess>> start(int count) {
    std::vector<std::unique_ptr<testing::ServerProcess>> servers;
    for (int i = 0; i < count; ++i) {
      std::string error;
      servers.push_back(testing::ServerProcess::start(scene_->path, {"--cache-mb", "2"}, error));
      EXPECT_NE(servers.back(), nullptr) << error;
    }
    return servers;
  }
  // The rays' answers from the one server at `address`: the reference.
  static void one_server_hits(const std::string& address, std::vector<Hit>& hits) {
    hits.assign(rays_.size(), Hit{});
    auto one = SceneClient::connect(address);
    ASSERT_TRUE(one.ok()) << one.status().message();
    ASSERT_TRUE((*one)->intersect(rays_, hits).ok());
  }
  static testing::PackedScene* scene_;
  static std::vector<Ray> rays_;
};
testing::PackedScene* ReplicaRouterTest::scene_ = nullptr;
std::vector<Ray> ReplicaRouterTest::rays_;

void expect_same_hits(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(std::memcmp(&a[i], &b[i], sizeof(Hit)), 0) << "ray " << i;
  }
}

// By brick (the default) and by ray: answers bitwise one server's, with
// every hit field and in occlusion; by brick every replica traces every ray
// and each owns a part of the bricks; a replica killed: its part goes to the
// next on the ring, later batches leave it out.
TEST_F(ReplicaRouterTest, RoutedAnswersAreOneServersBitwiseAndAKilledReplicaCostsOnlyTime) {
  for (const ReplicaRouting routing : {ReplicaRouting::kBricks, ReplicaRouting::kRays}) {
    const bool by_brick = routing == ReplicaRouting::kBricks;
    SCOPED_TRACE(by_brick ? "by brick" : "by ray");
    auto servers = start(3);
    ASSERT_EQ(servers.size(), 3u);
    for (const auto& s : servers) ASSERT_NE(s, nullptr);
    std::vector<Hit> reference;
    ASSERT_NO_FATAL_FAILURE(one_server_hits(servers[0]->address(), reference));
    std::vector<std::string> addresses;
    for (const auto& s : servers) addresses.push_back(s->address());
    auto router = ReplicaRouter::connect(addresses);
    ASSERT_TRUE(router.ok()) << router.status().message();
    EXPECT_EQ((*router)->routing(), ReplicaRouting::kBricks);
    (*router)->set_routing(routing);
    std::vector<Hit> hits(rays_.size());
    CallStats stats;
    ASSERT_TRUE((*router)->intersect(rays_, hits, {}, &stats).ok());
    expect_same_hits(hits, reference);
    // The batch's own counts, however many replicas traced each ray.
    EXPECT_EQ(stats.engine.rays(), rays_.size());
    uint64_t hit = 0;
    for (const Hit& h : reference) hit += h.is_hit();
    EXPECT_EQ(stats.engine.rays_hit(), hit);
    if (by_brick) {
      std::vector<uint32_t> owned;
      for (const auto& part : (*router)->plan_bricks()) {
        EXPECT_FALSE(part.empty());
        owned.insert(owned.end(), part.begin(), part.end());
      }
      std::sort(owned.begin(), owned.end());
      auto probe = SceneClient::connect(addresses[0]);
      ASSERT_TRUE(probe.ok());
      ASSERT_EQ(owned.size(), (*probe)->connected_scene().brick_count());
      ASSERT_GT(owned.size(), 3u);
      for (uint32_t b = 0; b < owned.size(); ++b) EXPECT_EQ(owned[b], b);
      // Fewer fields: the nearest still chosen by t and ids.
      CallOptions short_hits;
      short_hits.hit_fields = v1::HIT_FIELDS_T_IDS;
      std::vector<Hit> t_ids(rays_.size());
      ASSERT_TRUE((*router)->intersect(rays_, t_ids, short_hits).ok());
      for (std::size_t i = 0; i < rays_.size(); ++i) {
        ASSERT_EQ(std::memcmp(&t_ids[i].t, &reference[i].t, sizeof(float)), 0) << "ray " << i;
        ASSERT_EQ(t_ids[i].primitive_id, reference[i].primitive_id) << "ray " << i;
      }
    } else {
      for (const uint64_t load : (*router)->plan_loads(rays_)) EXPECT_GT(load, 0u);
    }
    std::vector<uint8_t> occluded(rays_.size()), occluded_reference(rays_.size());
    ASSERT_TRUE((*router)->occluded(rays_, occluded).ok());
    for (std::size_t i = 0; i < rays_.size(); ++i) occluded_reference[i] = reference[i].is_hit() ? 1 : 0;
    EXPECT_EQ(occluded, occluded_reference);

    servers[1]->signal(SIGKILL);
    EXPECT_EQ(servers[1]->stop(SIGKILL), -1);
    std::fill(hits.begin(), hits.end(), Hit{});
    ASSERT_TRUE((*router)->intersect(rays_, hits).ok());
    expect_same_hits(hits, reference);
    EXPECT_GE((*router)->failovers(), 1u);
    const std::vector<std::string> names = (*router)->replicas();
    const auto dead = static_cast<std::size_t>(std::find(names.begin(), names.end(), servers[1]->address()) -
                                               names.begin());
    ASSERT_LT(dead, names.size());
    if (by_brick) {
      EXPECT_TRUE((*router)->plan_bricks()[dead].empty());
    } else {
      EXPECT_EQ((*router)->plan_loads(rays_)[dead], 0u);
    }
  }
}

// A dns: name resolved again (connect_resolved with a resolver whose list
// changes, refresh 0): a replica that appears joins the ring and gets rays;
// one that leaves gets none; a failed resolution keeps the replicas known;
// answers stay one server's throughout.
TEST_F(ReplicaRouterTest, AResolvedNameIsResolvedAgainAndItsReplicasFollow) {
  auto servers = start(2);
  ASSERT_EQ(servers.size(), 2u);
  for (const auto& s : servers) ASSERT_NE(s, nullptr);
  std::vector<Hit> reference;
  ASSERT_NO_FATAL_FAILURE(one_server_hits(servers[0]->address(), reference));
  auto resolved =
      std::make_shared<Expected<std::vector<std::string>>>(std::vector<std::string>{servers[0]->address()});
  auto router =
      ReplicaRouter::connect_resolved([resolved] { return *resolved; }, {}, std::chrono::milliseconds(0));
  ASSERT_TRUE(router.ok()) << router.status().message();
  std::vector<Hit> hits(rays_.size());
  ASSERT_TRUE((*router)->intersect(rays_, hits).ok());
  expect_same_hits(hits, reference);
  EXPECT_EQ((*router)->replicas(), std::vector<std::string>{servers[0]->address()});

  // Scaled up: the next batch resolves again and routes over both.
  *resolved = std::vector<std::string>{servers[1]->address(), servers[0]->address()};
  std::fill(hits.begin(), hits.end(), Hit{});
  ASSERT_TRUE((*router)->intersect(rays_, hits).ok());
  expect_same_hits(hits, reference);
  ASSERT_EQ((*router)->replicas().size(), 2u);
  for (const uint64_t load : (*router)->plan_loads(rays_)) EXPECT_GT(load, 0u);

  // The resolver fails: the replicas known stay.
  *resolved = io_error("no such name");
  ASSERT_TRUE((*router)->intersect(rays_, hits).ok());
  EXPECT_EQ((*router)->replicas().size(), 2u);

  // Scaled down: the replica gone gets no rays, answers unchanged.
  *resolved = std::vector<std::string>{servers[1]->address()};
  std::fill(hits.begin(), hits.end(), Hit{});
  ASSERT_TRUE((*router)->intersect(rays_, hits).ok());
  expect_same_hits(hits, reference);
  EXPECT_EQ((*router)->replicas(), std::vector<std::string>{servers[1]->address()});
  EXPECT_EQ((*router)->failovers(), 0u);

  // A dns: target that is not one is refused by name.
  const auto wrong = ReplicaRouter::connect_dns("localhost:1");
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("not a dns: target"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore::client
