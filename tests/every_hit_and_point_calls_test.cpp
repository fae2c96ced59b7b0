// CountIntersections, ListIntersections and QueryPoints through a real
// `outcore serve` on a loopback port and the C++ client: the answers are
// bitwise the in-process engine's on the same store (under a budget a
// quarter of the scene on the server), list replies too large for a message
// are cut by the client, and bad requests are errors naming what is wrong.
#include <gtest/gtest.h>
#include <signal.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "client/cpp/scene_client.h"
#include "core/query/query_engine.h"
#include "tests/support/packed_scene.h"
#include "tests/support/server_process.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::ServerProcess;

class EveryHitAndPointCalls : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = testing::pack_test_scene({"gen:sphere?level=4", "gen:torus?nu=48&nv=24&cx=3"}, 200).release();
    std::string error;
    // --max-message-mb 1: a list of many hits needs several messages.
    server_ =
        ServerProcess::start(scene_->path, {"--cache-mb", "1", "--max-message-mb", "1"}, error).release();
    ASSERT_NE(server_, nullptr) << error;
    EngineOptions options;
    auto engine = QueryEngine::open(scene_->path, options);
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    engine_ = engine->release();
  }
  static void TearDownTestSuite() {
    delete engine_;
    if (server_ != nullptr) {
      EXPECT_EQ(server_->stop(SIGTERM), 0);
    }
    delete server_;
    delete scene_;
  }
  static std::unique_ptr<client::SceneClient> connect() {
    auto client = client::SceneClient::connect(server_->address());
    EXPECT_TRUE(client.ok()) << client.status().to_string();
    return std::move(client).value();
  }
  static std::vector<Ray> rays(std::size_t n) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<float> u(-4.0f, 4.0f);
    std::vector<Ray> out(n);
    for (Ray& r : out) {
      r.origin = {u(rng), u(rng), u(rng)};
      r.direction = Vec3f{u(rng) * 0.1f, u(rng) * 0.1f, u(rng) * 0.1f} - r.origin;
    }
    return out;
  }
  static std::vector<Vec3f> points(std::size_t n) {
    std::mt19937_64 rng(6);
    std::uniform_real_distribution<float> u(-4.5f, 4.5f);
    std::vector<Vec3f> out(n);
    for (Vec3f& p : out) p = {u(rng), u(rng), u(rng)};
    return out;
  }

  static testing::PackedScene* scene_;
  static ServerProcess* server_;
  static QueryEngine* engine_;
};

testing::PackedScene* EveryHitAndPointCalls::scene_ = nullptr;
ServerProcess* EveryHitAndPointCalls::server_ = nullptr;
QueryEngine* EveryHitAndPointCalls::engine_ = nullptr;

TEST_F(EveryHitAndPointCalls, CountsAndListsAreTheEnginesBitwiseAcrossMessages) {
  // ~1.5 hits a ray at 32 bytes: 60,000 rays' hits need more than 1 MiB.
  const std::vector<Ray> batch = rays(60'000);
  std::vector<uint32_t> expected_counts(batch.size());
  std::vector<RayHitRecord> expected;
  ASSERT_TRUE(engine_->all_hits(batch, expected_counts, &expected, {}).ok());
  ASSERT_GT(expected.size() * sizeof(Hit), std::size_t{1} << 20);
  auto client = connect();
  std::vector<uint32_t> counts(batch.size());
  ASSERT_TRUE(client->count_intersections(batch, counts).ok());
  EXPECT_EQ(counts, expected_counts);
  std::vector<uint32_t> list_counts(batch.size());
  std::vector<Hit> hits;
  client::CallStats stats;
  const Status listed = client->list_intersections(batch, list_counts, hits, {}, &stats);
  ASSERT_TRUE(listed.ok()) << listed.to_string();
  EXPECT_EQ(list_counts, expected_counts);
  ASSERT_EQ(hits.size(), expected.size());
  for (std::size_t k = 0; k < hits.size(); ++k)
    ASSERT_EQ(std::memcmp(&hits[k], &expected[k].hit, sizeof(Hit)), 0) << "hit " << k;
  EXPECT_GT(stats.messages, 1u);
  EXPECT_GT(stats.engine.brick_visits(), batch.size() / 2);
}

TEST_F(EveryHitAndPointCalls, PointAnswersAreTheEnginesBitwise) {
  const std::vector<Vec3f> batch = points(5000);
  std::vector<ClosestPoint> closest(batch.size());
  std::vector<uint8_t> inside(batch.size());
  ASSERT_TRUE(engine_->closest_points(batch, closest, {}).ok());
  ASSERT_TRUE(engine_->occupancy(batch, inside, {}).ok());
  auto client = connect();
  std::string answers;
  ASSERT_TRUE(client->query_points(batch, v1::POINT_QUERY_CLOSEST, answers).ok());
  ASSERT_EQ(answers.size(), batch.size() * 44);
  std::string distances, signed_distances, occupancy;
  ASSERT_TRUE(client->query_points(batch, v1::POINT_QUERY_DISTANCE, distances).ok());
  ASSERT_TRUE(client->query_points(batch, v1::POINT_QUERY_SIGNED_DISTANCE, signed_distances).ok());
  ASSERT_TRUE(client->query_points(batch, v1::POINT_QUERY_OCCUPANCY, occupancy).ok());
  std::size_t insiders = 0;
  for (std::size_t i = 0; i < batch.size(); ++i) {
    float record[11];
    std::memcpy(record, answers.data() + i * 44, 44);
    const ClosestPoint& c = closest[i];
    EXPECT_EQ(record[0], c.point.x);
    EXPECT_EQ(record[2], c.point.z);
    uint32_t ids[2];
    std::memcpy(ids, &record[3], 8);
    EXPECT_EQ(ids[0], c.geometry_id);
    EXPECT_EQ(ids[1], c.primitive_id);
    const float distance = static_cast<float>(std::sqrt(c.distance_squared));
    EXPECT_EQ(record[10], distance);
    float d, sd;
    std::memcpy(&d, distances.data() + i * 4, 4);
    std::memcpy(&sd, signed_distances.data() + i * 4, 4);
    EXPECT_EQ(d, distance);
    EXPECT_EQ(sd, inside[i] ? -distance : distance);
    EXPECT_EQ(static_cast<uint8_t>(occupancy[i]), inside[i]);
    insiders += inside[i];
  }
  EXPECT_GT(insiders, 10u);
}

TEST_F(EveryHitAndPointCalls, BadRequestsNameWhatIsWrong) {
  auto client = connect();
  std::string answers;
  const std::vector<Vec3f> batch = points(4);
  const Status no_kind = client->query_points(batch, v1::POINT_QUERY_UNSPECIFIED, answers);
  EXPECT_EQ(no_kind.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(no_kind.message(), "request.kind")) << no_kind.message();
  std::vector<Vec3f> bad = batch;
  bad[2].y = NAN;
  client::CallOptions strict;
  strict.strict = true;
  const Status refused = client->query_points(bad, v1::POINT_QUERY_DISTANCE, answers, strict);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(refused.message(), "point 2")) << refused.message();
  std::vector<Ray> bad_rays = rays(5);
  bad_rays[3].direction = {0, 0, 0};
  std::vector<uint32_t> counts(bad_rays.size());
  const Status bad_ray = client->count_intersections(bad_rays, counts, strict);
  EXPECT_EQ(bad_ray.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(bad_ray.message(), "ray 3")) << bad_ray.message();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
