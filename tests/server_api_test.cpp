// Tests of the gRPC API against a real `outcore serve` on a loopback port,
// through the C++ client library and raw stubs: 16 concurrent clients each get
// exactly their serial in-process answer; health reports SERVING; reflection
// lists the service; an expired deadline is DEADLINE_EXCEEDED and the server
// stays healthy; bad requests (byte lengths, counts, layout version and
// layout, NaN rays under strict, oversize messages and replies) are
// INVALID_ARGUMENT / RESOURCE_EXHAUSTED naming the field or ray, and the server
// answers a good request after each; a client cancelling mid-stream costs
// nothing; SIGTERM and SIGINT drain an in-flight stream and exit 0. Stats: a
// request's figures (proxy tests and skips, upper nodes, visits, cache) equal
// `outcore trace --stats-json` for the same rays on a fresh cache, GetStats
// sums them (streams included), and with --subtree-dir it reports the tier's
// loads and writes (none without).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "client/cpp/scene_client.h"
#include "core/io/npy.h"
#include "core/query/query_engine.h"
#include "core/store/scene_store.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"
#include "outcore/v1/scene_query.grpc.pb.h"
#include "proto/outcore/v1/query_stats_fields.h"
#include "tests/support/json_fields.h"
#include "tests/support/server_process.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::json_uint;
using testing::ServerProcess;
using testing::SubprocessResult;
using testing::TempDir;

std::string hit_bytes(std::span<const Hit> hits) {
  return std::string(reinterpret_cast<const char*>(hits.data()), hits.size_bytes());
}

v1::QueryRequest make_request(std::span<const Ray> rays, uint64_t sequence = 0) {
  v1::QueryRequest request;
  v1::RayBatch* batch = request.mutable_batch();
  batch->set_layout_version(1);
  batch->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  batch->set_ray_count(rays.size());
  batch->set_rays(reinterpret_cast<const char*>(rays.data()), rays.size_bytes());
  request.set_sequence(sequence);
  return request;
}

class ServerApi : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    store_ = dir_->file("scene");
    const SubprocessResult packed =
        testing::run_outcore({"pack", "gen:sphere?level=3", "gen:torus?cx=3", "-o", store_, "--brick-tris",
                              "200", "-q", "--no-sync"},
                             std::chrono::milliseconds(120'000));
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    auto engine = QueryEngine::open(store_, EngineOptions{});
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    engine_ = engine->release();
    std::string error;
    server_ =
        ServerProcess::start(
            store_, {"--max-message-mb", "1", "--log-level", "debug", "--stream-group-rays", "100000"}, error)
            .release();
    ASSERT_NE(server_, nullptr) << error;
  }
  static void TearDownTestSuite() {
    if (server_ != nullptr) {
      EXPECT_EQ(server_->stop(SIGTERM), 0) << server_->log();
    }
    delete server_;
    delete engine_;
    delete dir_;
    server_ = nullptr;
    engine_ = nullptr;
    dir_ = nullptr;
  }

  void SetUp() override {
    ASSERT_NE(server_, nullptr) << "suite setup failed";
    grpc::ChannelArguments arguments;
    arguments.SetMaxReceiveMessageSize(-1);
    arguments.SetMaxSendMessageSize(-1);
    channel_ = grpc::CreateCustomChannel(server_->address(), grpc::InsecureChannelCredentials(), arguments);
    stub_ = v1::SceneQuery::NewStub(channel_);
  }

  // The engine calls in the server's debug line for the last stream whose
  // line starts with `stream` (e.g. "IntersectStream: 12 chunks").
  static int last_stream_engine_calls(const std::string& log, const std::string& stream) {
    const auto line = log.rfind(stream);
    EXPECT_NE(line, std::string::npos) << log;
    if (line == std::string::npos) return -1;
    const auto calls = log.find(" engine calls", line);
    EXPECT_NE(calls, std::string::npos) << log.substr(line);
    if (calls == std::string::npos) return -1;
    const auto comma = log.rfind(", ", calls);
    return std::stoi(log.substr(comma + 2, calls - comma - 2));
  }

  static std::vector<Ray> rays(std::size_t n, uint32_t seed) {
    return testing::make_test_rays(engine_->store().manifest().bounds, n, seed);
  }
  static std::vector<Hit> serial_hits(std::span<const Ray> r) {
    std::vector<Hit> hits(r.size());
    EXPECT_TRUE(engine_->intersect(r, hits, QueryOptions{}).ok());
    return hits;
  }
  static std::vector<uint8_t> serial_occluded(std::span<const Ray> r) {
    std::vector<uint8_t> flags(r.size());
    EXPECT_TRUE(engine_->occluded(r, flags, QueryOptions{}).ok());
    return flags;
  }

  grpc::Status intersect(const v1::QueryRequest& request, v1::IntersectResponse* response = nullptr) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    v1::IntersectResponse local;
    return stub_->Intersect(&context, request, response ? response : &local);
  }

  static v1::ServerStats server_stats(v1::SceneQuery::Stub& stub) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    v1::ServerStats stats;
    const grpc::Status status = stub.GetStats(&context, v1::GetStatsRequest(), &stats);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return stats;
  }

  // A good request is answered right (the server is still serving).
  void expect_serving() {
    const std::vector<Ray> r = rays(500, 99);
    v1::IntersectResponse response;
    const grpc::Status status = intersect(make_request(r), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(response.hits() == hit_bytes(serial_hits(r)));
  }

  void expect_error(const v1::QueryRequest& request, grpc::StatusCode code,
                    const std::vector<std::string>& parts) {
    const grpc::Status status = intersect(request);
    EXPECT_EQ(status.error_code(), code) << status.error_message();
    for (const std::string& part : parts) {
      EXPECT_TRUE(contains(status.error_message(), part))
          << "'" << part << "' not in: " << status.error_message();
    }
    expect_serving();
  }

  static TempDir* dir_;
  static std::string store_;
  static QueryEngine* engine_;
  static ServerProcess* server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SceneQuery::Stub> stub_;
};

TempDir* ServerApi::dir_ = nullptr;
std::string ServerApi::store_;
QueryEngine* ServerApi::engine_ = nullptr;
ServerProcess* ServerApi::server_ = nullptr;

TEST_F(ServerApi, SixteenConcurrentClientsGetTheirSerialAnswers) {
  constexpr int kClients = 16;
  std::vector<std::vector<Ray>> batches;
  std::vector<std::string> want;
  for (int c = 0; c < kClients; ++c) {
    batches.push_back(rays(1500 + 700 * c, 1000 + c));
    if (c % 2 == 0) {
      want.push_back(hit_bytes(serial_hits(batches.back())));
    } else {
      const std::vector<uint8_t> flags = serial_occluded(batches.back());
      want.emplace_back(flags.begin(), flags.end());
    }
  }
  std::vector<std::string> got(kClients);
  std::vector<std::string> errors(kClients);
  std::vector<std::thread> threads;
  for (int c = 0; c < kClients; ++c) {
    threads.emplace_back([&, c] {
      auto client = client::SceneClient::connect(server_->address());
      if (!client.ok()) {
        errors[c] = client.status().to_string();
        return;
      }
      client::CallOptions options;
      options.chunk_rays = c % 4 == 1 ? 1000 : 0;  // some clients stream
      options.deadline_seconds = 120;
      for (int repeat = 0; repeat < 2; ++repeat) {
        Status status;
        if (c % 2 == 0) {
          std::vector<Hit> hits(batches[c].size());
          status = (*client)->intersect(batches[c], hits, options);
          got[c] = hit_bytes(hits);
        } else {
          std::vector<uint8_t> flags(batches[c].size());
          status = (*client)->occluded(batches[c], flags, options);
          got[c].assign(flags.begin(), flags.end());
        }
        if (!status.ok()) errors[c] = status.to_string();
        if (!errors[c].empty() || got[c] != want[c]) return;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (int c = 0; c < kClients; ++c) {
    EXPECT_EQ(errors[c], "") << "client " << c;
    EXPECT_TRUE(got[c] == want[c]) << "client " << c << " got another answer than its serial one";
  }
}

TEST_F(ServerApi, ClientLibraryStreamsBigBatchesAndReportsStats) {
  client::ConnectOptions over_grpc;
  over_grpc.shared_memory = false;  // what is tested here is the streamed bytes path
  auto client = client::SceneClient::connect(server_->address(), over_grpc);
  ASSERT_TRUE(client.ok()) << client.status().to_string();
  EXPECT_EQ((*client)->connected_scene().max_message_bytes(), uint64_t{1} << 20);
  EXPECT_LT((*client)->max_chunk_rays(), 40'000u);
  const std::vector<Ray> r = rays(90'000, 5);
  std::vector<Hit> hits(r.size());
  client::CallStats stats;
  const v1::ServerStats before = server_stats(*stub_);
  ASSERT_TRUE((*client)->intersect(r, hits, {}, &stats).ok());
  EXPECT_TRUE(hit_bytes(hits) == hit_bytes(serial_hits(r)));
  EXPECT_EQ(stats.messages, 3u);
  EXPECT_EQ(stats.engine.rays(), r.size());
  uint64_t hit_count = 0;
  for (const Hit& h : hits) hit_count += h.is_hit();
  EXPECT_EQ(stats.engine.rays_hit(), hit_count);
  // Zero rays: nothing to send, nothing to answer.
  EXPECT_TRUE((*client)->intersect({}, {}, {}).ok());
  EXPECT_EQ((*client)->intersect(r, std::span<Hit>(hits).first(5), {}).code(), StatusCode::kInvalidArgument);

  auto server_stats = (*client)->stats();
  ASSERT_TRUE(server_stats.ok()) << server_stats.status().to_string();
  EXPECT_GE(server_stats->requests(), 3u);
  EXPECT_GE(server_stats->rays(), r.size());
  EXPECT_GT(server_stats->cache_hits() + server_stats->cache_misses(), 0u);
  EXPECT_EQ(server_stats->cache_budget_bytes(), uint64_t{1024} << 20);
  EXPECT_EQ(server_stats->eviction_policy(), "lru");
  // The engine's figures summed over the replies are what the server added up.
  EXPECT_GT(stats.engine.upper_nodes_visited(), 0u);
  EXPECT_EQ(server_stats->brick_visits() - before.brick_visits(), stats.engine.brick_visits());
  EXPECT_EQ(server_stats->proxy_tests() - before.proxy_tests(), stats.engine.proxy_tests());
  EXPECT_EQ(server_stats->bricks_skipped_by_proxy() - before.bricks_skipped_by_proxy(),
            stats.engine.bricks_skipped_by_proxy());
  EXPECT_EQ(server_stats->rays_traced_ahead() - before.rays_traced_ahead(), stats.engine.rays_traced_ahead());
  EXPECT_EQ(server_stats->proxy_bytes(), engine_->proxies()->memory_bytes());
  // No subtree tier on this server: no directory, every tier figure 0.
  EXPECT_EQ(server_stats->subtree_dir(), "");
  EXPECT_EQ(server_stats->subtree_loads() + server_stats->subtree_writes() + server_stats->subtree_rejects() +
                server_stats->subtree_bytes_read() + server_stats->subtree_bytes_written() +
                server_stats->subtree_files() + server_stats->subtree_file_bytes(),
            0u);
  EXPECT_EQ(server_stats->subtree_load_seconds(), 0.0);
  EXPECT_EQ(stats.engine.subtree_loads() + stats.engine.subtree_writes() + stats.engine.subtree_rejects(),
            0u);
}

// The wire's QueryStats and the list the server and client convert it with
// (proto/outcore/v1/query_stats_fields.h) name the same fields.
TEST(WireQueryStats, TheConversionListNamesEveryFieldOfTheMessage) {
  std::vector<std::string> listed;
#define OUTCORE_LIST_WIRE_FIELD(name) listed.push_back(#name);
  OUTCORE_WIRE_QUERY_STATS(OUTCORE_LIST_WIRE_FIELD)
#undef OUTCORE_LIST_WIRE_FIELD
  const google::protobuf::Descriptor* message = v1::QueryStats::descriptor();
  ASSERT_EQ(listed.size(), static_cast<std::size_t>(message->field_count()));
  for (int i = 0; i < message->field_count(); ++i) {
    EXPECT_EQ(listed[i], message->field(i)->name()) << "field " << i << " of outcore.v1.QueryStats";
  }
}

// A scene of three bricks, wholly resident: a large enough request goes
// through the bricks' one Embree scene (rays_in_brick_set on the wire) and
// answers bitwise as the engine does brick by brick.
TEST(ServerBrickSet, ALargeRequestOnAResidentSmallSceneGoesThroughTheSetAndAnswersAsBrickByBrick) {
  TempDir dir;
  const std::string store = dir.file("three");
  const SubprocessResult packed = testing::run_outcore(
      {"pack", "gen:sphere?level=4", "-o", store, "--brick-tris", "2000", "-q", "--no-sync"},
      std::chrono::milliseconds(120'000));
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  auto engine = QueryEngine::open(store, EngineOptions{});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  ASSERT_GT((*engine)->store().brick_count(), 1u);
  ASSERT_LE((*engine)->store().brick_count(), 16u);
  const std::vector<Ray> r = testing::make_test_rays((*engine)->store().manifest().bounds, 20000, 88);
  std::vector<Hit> brick_by_brick(r.size());
  QueryOptions walked;
  walked.brick_set = false;
  ASSERT_TRUE((*engine)->intersect(r, brick_by_brick, walked).ok());

  std::string error;
  auto server = ServerProcess::start(store, {}, error);
  ASSERT_NE(server, nullptr) << error;
  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  for (int call = 0; call < 2; ++call) {  // cold (bricks built), then warm (all resident)
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    v1::IntersectResponse response;
    const grpc::Status status = stub->Intersect(&context, make_request(r), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(response.hits() == hit_bytes(brick_by_brick)) << "call " << call;
    if (call == 1) {
      EXPECT_EQ(response.stats().rays_in_brick_set(), r.size());
      EXPECT_EQ(response.stats().brick_visits(), 0u);
      EXPECT_EQ(response.stats().brick_builds(), 0u);
    }
  }
  grpc::ClientContext stats_context;
  v1::ServerStats totals;
  ASSERT_TRUE(stub->GetStats(&stats_context, v1::GetStatsRequest(), &totals).ok());
  EXPECT_EQ(totals.rays_in_brick_set(), r.size()) << "the warm call's rays, summed by the server";
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

// The strongest check of the per-request figures: the same rays on the same
// store with a fresh cache, once through a fresh server and once through
// `outcore trace`, give the same counts. Both run one engine thread: how a
// batch's candidates split into visits and proxy skips can change with the
// thread count (their sum cannot, nor can any answer).
TEST_F(ServerApi, PerRequestFiguresEqualTracesForTheSameRaysOnAFreshCache) {
  std::string error;
  auto fresh = ServerProcess::start(store_, {"--threads", "1"}, error);
  ASSERT_NE(fresh, nullptr) << error;
  const std::vector<Ray> r = rays(3000, 60);
  const std::string rays_path = dir_->file("fresh-rays.npy");
  ASSERT_TRUE(write_rays_npy(rays_path, r).ok());
  const std::string json_path = dir_->file("fresh-trace.json");
  const SubprocessResult traced =
      testing::run_outcore({"trace", store_, "--rays", rays_path, "-o", dir_->file("fresh-hits.npy"),
                            "--threads", "1", "--stats-json", json_path},
                           std::chrono::milliseconds(120'000));
  ASSERT_TRUE(traced.succeeded()) << traced.describe();
  const std::string json = testing::read_file_bytes(json_path);

  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(fresh->address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::IntersectResponse response;
  const grpc::Status status = stub->Intersect(&context, make_request(r), &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  const v1::QueryStats& s = response.stats();
  // The budget holds the scene, so the proxies are asked at builds (a brick
  // passed over only when no queued ray may hit it): tests, maybe no skips.
  EXPECT_GT(s.proxy_tests(), 0u);
  const std::pair<const char*, uint64_t> figures[] = {
      {"rays", s.rays()},
      {"invalid_rays", s.invalid_rays()},
      {"rays_hit", s.rays_hit()},
      {"upper_nodes_visited", s.upper_nodes_visited()},
      {"brick_visits", s.brick_visits()},
      {"proxy_tests", s.proxy_tests()},
      {"bricks_skipped_by_proxy", s.bricks_skipped_by_proxy()},
      {"rays_traced_ahead", s.rays_traced_ahead()},
      {"brick_acquisitions", s.brick_acquisitions()},
      {"cache_hits", s.cache_hits()},
      {"cache_misses", s.cache_misses()},
      {"brick_builds", s.brick_builds()},
      {"evictions", s.evictions()},
      {"subtree_loads", s.subtree_loads()},
      {"subtree_writes", s.subtree_writes()},
  };
  for (const auto& [key, value] : figures)
    EXPECT_EQ(value, json_uint(json, key)) << key << "; trace: " << json;
  EXPECT_GT(s.seconds_total(), 0.0);
  EXPECT_GE(s.seconds_total(), s.seconds_upper());
  EXPECT_GE(s.seconds_brick_builds(), 0.0);

  // The only request this server answered: its figures are the server's.
  const v1::ServerStats totals = server_stats(*stub);
  EXPECT_EQ(totals.brick_visits(), s.brick_visits());
  EXPECT_EQ(totals.proxy_tests(), s.proxy_tests());
  EXPECT_EQ(totals.bricks_skipped_by_proxy(), s.bricks_skipped_by_proxy());
  EXPECT_EQ(totals.rays_traced_ahead(), s.rays_traced_ahead());
  EXPECT_EQ(totals.proxy_bytes(), json_uint(json, "proxy_bytes"));
  EXPECT_EQ(fresh->stop(SIGTERM), 0) << fresh->log();
}

// With --subtree-dir a server saves the bricks it builds and, once its budget
// has evicted them, loads them back instead of building; GetStats and the
// replies report both.
TEST_F(ServerApi, SubtreeTierLoadsAndWritesReachGetStatsAndTheReplies) {
  // Bigger bricks than the suite's store: 28 of about 1,000 triangles, 2.2 MiB
  // as bvh, so a 1 MiB budget evicts and the second batch loads from the tier.
  TempDir local;
  const std::string store = local.file("scene");
  const SubprocessResult packed = testing::run_outcore({"pack", "gen:sphere?level=5", "gen:torus?cx=3", "-o",
                                                        store, "--brick-tris", "1000", "-q", "--no-sync"},
                                                       std::chrono::milliseconds(120'000));
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  auto opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok()) << opened.status().to_string();
  const uint32_t brick_count = (*opened)->brick_count();
  const std::string tier = local.file("subtrees");
  std::string error;
  auto server = ServerProcess::start(
      store, {"--brick-accel", "bvh", "--cache-mb", "1", "--subtree-dir", tier, "--threads", "1"}, error);
  ASSERT_NE(server, nullptr) << error;
  auto client = client::SceneClient::connect(server->address());
  ASSERT_TRUE(client.ok()) << client.status().to_string();
  const std::vector<Ray> r = testing::make_test_rays((*opened)->manifest().bounds, 3000, 61);
  std::vector<Hit> first(r.size());
  std::vector<Hit> second(r.size());
  client::CallStats a;
  client::CallStats b;
  ASSERT_TRUE((*client)->intersect(r, first, {}, &a).ok());
  ASSERT_TRUE((*client)->intersect(r, second, {}, &b).ok());
  EXPECT_TRUE(hit_bytes(first) == hit_bytes(second));
  EXPECT_GT(a.engine.subtree_writes(), 0u);
  EXPECT_GT(b.engine.subtree_loads(), 0u) << "the second batch built again instead of loading";

  auto stats = (*client)->stats();
  ASSERT_TRUE(stats.ok()) << stats.status().to_string();
  EXPECT_EQ(stats->subtree_dir(), tier);
  EXPECT_GT(stats->evictions(), 0u) << "the budget held the scene: nothing to reload";
  EXPECT_GT(stats->subtree_writes(), 0u);
  EXPECT_EQ(stats->subtree_writes(), stats->brick_builds()) << "each brick built is written once";
  EXPECT_LE(stats->subtree_writes(), brick_count);
  EXPECT_GT(stats->subtree_loads(), 0u);
  EXPECT_EQ(stats->subtree_rejects(), 0u);
  EXPECT_GT(stats->subtree_bytes_written(), 0u);
  EXPECT_GT(stats->subtree_bytes_read(), 0u);
  EXPECT_GE(stats->subtree_load_seconds(), 0.0);
  EXPECT_EQ(stats->subtree_files(), stats->subtree_writes());
  EXPECT_EQ(stats->subtree_file_bytes(), stats->subtree_bytes_written());
  EXPECT_EQ(stats->subtree_write_failures(), 0u);
  EXPECT_EQ(stats->subtree_writes_too_large(), 0u);
  EXPECT_EQ(stats->subtree_files_evicted(), 0u) << "an unbounded tier removed files";
  EXPECT_GT(stats->subtree_write_seconds(), 0.0);
  // The replies' figures add up to the server's (nothing else ran on it).
  EXPECT_EQ(a.engine.subtree_loads() + b.engine.subtree_loads(), stats->subtree_loads());
  EXPECT_EQ(a.engine.subtree_loads_kept() + b.engine.subtree_loads_kept(), stats->subtree_loads_kept());
  EXPECT_EQ(a.engine.subtree_loads_recycled() + b.engine.subtree_loads_recycled(),
            stats->subtree_loads_recycled());
  EXPECT_EQ(stats->subtree_loads_kept() + stats->subtree_loads_recycled(), stats->subtree_loads())
      << "the server wrote the files: each load reads into a kept or a recycled copy, mapping nothing";
  EXPECT_EQ(a.engine.subtree_writes() + b.engine.subtree_writes(), stats->subtree_writes());
  EXPECT_EQ(a.engine.subtree_bytes_read() + b.engine.subtree_bytes_read(), stats->subtree_bytes_read());
  EXPECT_EQ(a.engine.subtree_bytes_written() + b.engine.subtree_bytes_written(),
            stats->subtree_bytes_written());
  EXPECT_EQ(a.engine.brick_builds() + b.engine.brick_builds(), stats->brick_builds());
  // And they print as `outcore trace --stats` prints them.
  const std::string text = client::to_query_stats(b.engine).to_text();
  EXPECT_TRUE(contains(text, "subtree tier: " + std::to_string(b.engine.subtree_loads()) + " loads")) << text;
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();

  // A tier bounded below the files written removes files to stay within it.
  const std::string bounded_tier = local.file("bounded");
  auto bounded = ServerProcess::start(store,
                                      {"--brick-accel", "bvh", "--cache-mb", "1", "--subtree-dir",
                                       bounded_tier, "--subtree-dir-mb", "1", "--threads", "1"},
                                      error);
  ASSERT_NE(bounded, nullptr) << error;
  auto bounded_client = client::SceneClient::connect(bounded->address());
  ASSERT_TRUE(bounded_client.ok()) << bounded_client.status().to_string();
  std::vector<Hit> third(r.size());
  ASSERT_TRUE((*bounded_client)->intersect(r, third, {}).ok());
  EXPECT_TRUE(hit_bytes(third) == hit_bytes(first));
  auto bounded_stats = (*bounded_client)->stats();
  ASSERT_TRUE(bounded_stats.ok()) << bounded_stats.status().to_string();
  ASSERT_GT(stats->subtree_bytes_written(), uint64_t{1} << 20) << "the files fit 1 MiB: nothing to remove";
  EXPECT_GT(bounded_stats->subtree_files_evicted(), 0u);
  EXPECT_LE(bounded_stats->subtree_file_bytes(), uint64_t{1} << 20);
  EXPECT_EQ(bounded_stats->subtree_files() + bounded_stats->subtree_files_evicted() +
                bounded_stats->subtree_writes_too_large(),
            bounded_stats->subtree_writes());
  EXPECT_EQ(bounded->stop(SIGTERM), 0) << bounded->log();
}

TEST_F(ServerApi, SceneInfoDescribesTheStore) {
  auto client = client::SceneClient::connect(server_->address());
  ASSERT_TRUE(client.ok()) << client.status().to_string();
  const v1::SceneInfo& info = (*client)->connected_scene();
  const Manifest& manifest = engine_->store().manifest();
  EXPECT_EQ(info.triangle_count(), manifest.triangle_count);
  EXPECT_EQ(info.brick_count(), engine_->store().brick_count());
  ASSERT_EQ(info.inputs_size(), 2);
  EXPECT_EQ(info.inputs(0).spec(), "gen:sphere?level=3");
  EXPECT_EQ(info.inputs(1).triangle_count(), manifest.inputs[1].triangle_count);
  ASSERT_EQ(info.bounds_lo_size(), 3);
  EXPECT_EQ(info.bounds_lo(0), manifest.bounds.lo.x);
  EXPECT_EQ(info.bounds_hi(2), manifest.bounds.hi.z);
  EXPECT_EQ(info.brick_accel(), kDefaultBrickAccel);
  EXPECT_EQ(info.server_version(), OUTCORE_VERSION);
  EXPECT_EQ(info.upper_depth(), manifest.upper.depth());
}

void expect_health_serving(const std::shared_ptr<grpc::Channel>& channel) {
  auto health = grpc::health::v1::Health::NewStub(channel);
  for (const std::string service : {"", "outcore.v1.SceneQuery"}) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    grpc::health::v1::HealthCheckRequest request;
    request.set_service(service);
    grpc::health::v1::HealthCheckResponse response;
    const grpc::Status status = health->Check(&context, request, &response);
    ASSERT_TRUE(status.ok()) << "'" << service << "': " << status.error_message();
    EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING) << "'" << service << "'";
  }
}

TEST_F(ServerApi, HealthReportsServing) {
  expect_health_serving(channel_);
}

TEST_F(ServerApi, ReflectionListsTheService) {
  auto reflection = grpc::reflection::v1alpha::ServerReflection::NewStub(channel_);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto stream = reflection->ServerReflectionInfo(&context);
  grpc::reflection::v1alpha::ServerReflectionRequest request;
  request.set_list_services("");
  ASSERT_TRUE(stream->Write(request));
  // And the file that defines it, so grpcurl-style tools can build requests.
  request.set_file_containing_symbol("outcore.v1.SceneQuery");
  ASSERT_TRUE(stream->Write(request));
  stream->WritesDone();
  grpc::reflection::v1alpha::ServerReflectionResponse response;
  ASSERT_TRUE(stream->Read(&response));
  std::set<std::string> names;
  for (const auto& s : response.list_services_response().service()) names.insert(s.name());
  EXPECT_TRUE(names.count("outcore.v1.SceneQuery")) << "services listed: " << names.size();
  EXPECT_TRUE(names.count("grpc.health.v1.Health"));
  ASSERT_TRUE(stream->Read(&response));
  EXPECT_GT(response.file_descriptor_response().file_descriptor_proto_size(), 0);
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ServerApi, ExpiredDeadlineIsDeadlineExceededAndTheServerStaysHealthy) {
  auto client = client::SceneClient::connect(server_->address());
  ASSERT_TRUE(client.ok()) << client.status().to_string();
  const std::vector<Ray> r = rays(200'000, 6);
  std::vector<Hit> hits(r.size());
  client::CallOptions options;
  options.deadline_seconds = 0.002;
  const Status status = (*client)->intersect(r, hits, options);
  EXPECT_EQ(status.code(), StatusCode::kCancelled) << status.to_string();
  EXPECT_TRUE(contains(status.message(), "DEADLINE_EXCEEDED")) << status.message();
  // Also a unary call straight on the stub.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(1));
  v1::IntersectResponse response;
  const std::vector<Ray> small = rays(30'000, 7);
  EXPECT_EQ(stub_->Intersect(&context, make_request(small), &response).error_code(),
            grpc::StatusCode::DEADLINE_EXCEEDED);
  expect_serving();
  expect_health_serving(channel_);
}

TEST_F(ServerApi, MalformedBatchesAreInvalidArgumentNamingTheField) {
  const std::vector<Ray> r = rays(10, 8);
  v1::QueryRequest request = make_request(r);
  request.mutable_batch()->mutable_rays()->push_back('x');
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.rays", "321 bytes", "32-byte"});

  request = make_request(r);
  request.mutable_batch()->set_ray_count(11);
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.ray_count is 11", "holds 10 rays"});

  request = make_request(r);
  request.mutable_batch()->set_layout_version(2);
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.layout_version is 2"});

  request = make_request(r);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_UNSPECIFIED);
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.ray_layout", "RAY_LAYOUT_UNSPECIFIED"});

  request = make_request(r);
  request.mutable_batch()->set_ray_layout(static_cast<v1::RayLayout>(77));
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.ray_layout", "77"});

  // No batch at all: layout version 0.
  expect_error(v1::QueryRequest(), grpc::StatusCode::INVALID_ARGUMENT, {"batch.layout_version is 0"});

  // Six floats per ray: 10 rays are 240 bytes, so 320 bytes are 13.33 rays.
  request = make_request(r);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X6);
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"batch.rays", "24-byte", "RAY_LAYOUT_F32X6"});
}

TEST_F(ServerApi, SixFloatRaysGetDefaultLimits) {
  std::vector<Ray> r = rays(2000, 9);
  std::string six;
  for (Ray& ray : r) {
    const float row[6] = {ray.origin.x,    ray.origin.y,    ray.origin.z,
                          ray.direction.x, ray.direction.y, ray.direction.z};
    six.append(reinterpret_cast<const char*>(row), sizeof row);
    ray.tnear = 0;
    ray.tfar = std::numeric_limits<float>::infinity();
  }
  v1::QueryRequest request = make_request(r);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X6);
  request.mutable_batch()->set_rays(six);
  v1::IntersectResponse response;
  const grpc::Status status = intersect(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_TRUE(response.hits() == hit_bytes(serial_hits(r)));
}

TEST_F(ServerApi, StrictNanRayIsNamedByIndex) {
  std::vector<Ray> r = rays(100, 10);
  r[37].direction.y = std::numeric_limits<float>::quiet_NaN();
  v1::QueryRequest request = make_request(r);
  request.set_strict(true);
  expect_error(request, grpc::StatusCode::INVALID_ARGUMENT, {"ray 37:"});
  // Without strict it is a miss, counted as invalid.
  request.set_strict(false);
  v1::IntersectResponse response;
  ASSERT_TRUE(intersect(request, &response).ok());
  EXPECT_EQ(response.stats().invalid_rays(), 1u);
  Hit h;
  std::memcpy(static_cast<void*>(&h), response.hits().data() + 37 * sizeof(Hit), sizeof h);
  EXPECT_FALSE(h.is_hit());

  // In a stream the index counts every ray the call sent, and the chunk is named.
  grpc::ClientContext context;
  auto stream = stub_->IntersectStream(&context);
  std::vector<Ray> chunk = rays(100, 11);
  for (uint64_t c = 0; c < 3; ++c) {
    if (c == 2) chunk[37].origin.x = std::numeric_limits<float>::infinity();
    v1::QueryRequest part = make_request(chunk, c);
    part.set_strict(true);
    if (!stream->Write(part)) break;
  }
  stream->WritesDone();
  int replies = 0;
  while (stream->Read(&response)) ++replies;
  const grpc::Status status = stream->Finish();
  EXPECT_EQ(replies, 2);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(contains(status.error_message(), "ray 237 (chunk 2, ray 37 of the chunk)"))
      << status.error_message();
  expect_serving();
}

// Embree aborts on components beyond +-1.844e18; the engine counts such rays
// as invalid: misses, or under strict an error naming the ray.
TEST_F(ServerApi, ComponentsBeyondTheIntersectorsRangeAreInvalidRaysNotFatal) {
  std::vector<Ray> r = rays(100, 13);
  r[12].origin.x = 3e38f;
  r[70].direction.z = -2e19f;
  {
    grpc::ClientContext context;
    v1::IntersectResponse response;
    const grpc::Status status = stub_->Intersect(&context, make_request(r), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(response.stats().invalid_rays(), 2u);
    ASSERT_EQ(response.hits().size(), r.size() * sizeof(Hit));
    Hit hit;
    const Hit miss;
    for (const std::size_t i : {std::size_t{12}, std::size_t{70}}) {
      std::memcpy(&hit, response.hits().data() + i * sizeof(Hit), sizeof(Hit));
      EXPECT_EQ(std::memcmp(&hit, &miss, sizeof(Hit)), 0) << "ray " << i << " is not a clean miss";
    }
  }
  v1::QueryRequest strict = make_request(r);
  strict.set_strict(true);
  expect_error(strict, grpc::StatusCode::INVALID_ARGUMENT, {"ray 12:", "1.844e18"});
  r[12].origin.x = 0;
  grpc::ClientContext context;
  v1::OccludedResponse response;
  strict = make_request(r);
  strict.set_strict(true);
  const grpc::Status status = stub_->Occluded(&context, strict, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(contains(status.error_message(), "ray 70:")) << status.error_message();
  expect_serving();
}

TEST_F(ServerApi, OversizeMessagesAreResourceExhausted) {
  // 40,000 rays: 1.28 MB against the 1 MiB limit.
  const std::vector<Ray> big = rays(40'000, 12);
  expect_error(make_request(big), grpc::StatusCode::RESOURCE_EXHAUSTED, {});
  // Six-float rays fit (960 KB) but their hits would not: refused up front.
  std::string six(big.size() * 24, '\0');
  for (size_t i = 0; i < big.size(); ++i) std::memcpy(six.data() + i * 24, &big[i], 24);
  v1::QueryRequest request = make_request(big);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X6);
  request.mutable_batch()->set_rays(six);
  expect_error(request, grpc::StatusCode::RESOURCE_EXHAUSTED,
               {"reply", "max message size", "--max-message-mb"});
}

TEST_F(ServerApi, StreamRepliesEchoSequencesInOrder) {
  grpc::ClientContext context;
  auto stream = stub_->OccludedStream(&context);
  std::vector<std::vector<Ray>> chunks;
  for (uint64_t c = 0; c < 5; ++c) {
    chunks.push_back(rays(300 + 100 * c, 20 + c));
    ASSERT_TRUE(stream->Write(make_request(chunks.back(), 1000 + c)));
  }
  stream->WritesDone();
  v1::OccludedResponse response;
  for (uint64_t c = 0; c < 5; ++c) {
    ASSERT_TRUE(stream->Read(&response));
    EXPECT_EQ(response.sequence(), 1000 + c);
    EXPECT_EQ(response.ray_count(), chunks[c].size());
    const std::vector<uint8_t> want = serial_occluded(chunks[c]);
    EXPECT_TRUE(response.occluded() == std::string(want.begin(), want.end())) << "chunk " << c;
  }
  EXPECT_FALSE(stream->Read(&response));
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(ServerApi, ChunksQueuedWhileTheEngineIsBusyAreTracedTogetherWithOneReplyEach) {
  // A big first chunk keeps the engine busy while the small ones queue up
  // behind it; one chunk in the middle is strict (never grouped with the
  // others). Every reply must still be its chunk's serial answer, in order.
  const v1::ServerStats before = server_stats(*stub_);
  grpc::ClientContext context;
  auto stream = stub_->IntersectStream(&context);
  std::vector<std::vector<Ray>> chunks;
  constexpr uint64_t kChunks = 12;
  for (uint64_t c = 0; c < kChunks; ++c) {
    chunks.push_back(rays(c == 0 ? 30000 : 700 + 10 * c, 40 + c));
    v1::QueryRequest request = make_request(chunks.back(), c);
    request.set_strict(c == 6);
    ASSERT_TRUE(stream->Write(request));
  }
  stream->WritesDone();
  v1::IntersectResponse response;
  uint64_t rays_hit = 0;
  uint64_t want_hit = 0;
  v1::QueryStats sums;
  for (uint64_t c = 0; c < kChunks; ++c) {
    ASSERT_TRUE(stream->Read(&response)) << "reply " << c;
    EXPECT_EQ(response.sequence(), c);
    EXPECT_EQ(response.ray_count(), chunks[c].size());
    EXPECT_EQ(response.stats().rays(), chunks[c].size()) << "chunk " << c;
    const std::vector<Hit> want = serial_hits(chunks[c]);
    EXPECT_TRUE(response.hits() == hit_bytes(want)) << "chunk " << c;
    rays_hit += response.stats().rays_hit();
    for (const Hit& hit : want) want_hit += std::isfinite(hit.t) ? 1 : 0;
    const v1::QueryStats& s = response.stats();
    sums.set_brick_visits(sums.brick_visits() + s.brick_visits());
    sums.set_proxy_tests(sums.proxy_tests() + s.proxy_tests());
    sums.set_bricks_skipped_by_proxy(sums.bricks_skipped_by_proxy() + s.bricks_skipped_by_proxy());
    sums.set_upper_nodes_visited(sums.upper_nodes_visited() + s.upper_nodes_visited());
  }
  EXPECT_EQ(rays_hit, want_hit) << "the replies' figures must add up to the stream's";
  EXPECT_FALSE(stream->Read(&response));
  EXPECT_TRUE(stream->Finish().ok());
  // Also the new figures: each engine call's are in one reply only.
  const v1::ServerStats after = server_stats(*stub_);
  EXPECT_GT(sums.upper_nodes_visited(), 0u);
  EXPECT_EQ(after.brick_visits() - before.brick_visits(), sums.brick_visits());
  EXPECT_EQ(after.proxy_tests() - before.proxy_tests(), sums.proxy_tests());
  EXPECT_EQ(after.bricks_skipped_by_proxy() - before.bricks_skipped_by_proxy(),
            sums.bricks_skipped_by_proxy());
  // The server's debug line for the stream: fewer engine calls than chunks.
  const int engine_calls = last_stream_engine_calls(server_->log(), "IntersectStream: 12 chunks");
  EXPECT_GE(engine_calls, 3) << "the strict chunk is traced on its own";
  EXPECT_LT(engine_calls, static_cast<int>(kChunks));
}

TEST_F(ServerApi, GatheringTracesAStreamInOneCallAndStillAnswersAClientWaitingForEachReply) {
  std::string error;
  auto gathering = ServerProcess::start(
      store_, {"--log-level", "debug", "--stream-group-rays", "100000", "--stream-gather-ms", "400"}, error);
  ASSERT_NE(gathering, nullptr) << error;
  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(gathering->address(), grpc::InsecureChannelCredentials()));
  std::vector<std::vector<Ray>> chunks;
  for (uint64_t c = 0; c < 8; ++c) chunks.push_back(rays(2000, 70 + c));
  {
    // Chunks 20 ms apart: the tracer waits for all of them.
    grpc::ClientContext context;
    auto stream = stub->IntersectStream(&context);
    for (uint64_t c = 0; c < chunks.size(); ++c) {
      ASSERT_TRUE(stream->Write(make_request(chunks[c], c)));
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    stream->WritesDone();
    v1::IntersectResponse response;
    for (uint64_t c = 0; c < chunks.size(); ++c) {
      ASSERT_TRUE(stream->Read(&response)) << "reply " << c;
      EXPECT_EQ(response.sequence(), c);
      EXPECT_TRUE(response.hits() == hit_bytes(serial_hits(chunks[c]))) << "chunk " << c;
    }
    EXPECT_TRUE(stream->Finish().ok());
    EXPECT_EQ(last_stream_engine_calls(gathering->log(), "IntersectStream: 8 chunks"), 1);
  }
  {
    // One chunk, then its reply, then the next: each is traced once the
    // gathering wait runs out.
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    auto stream = stub->IntersectStream(&context);
    v1::IntersectResponse response;
    for (uint64_t c = 0; c < 3; ++c) {
      const auto start = std::chrono::steady_clock::now();
      ASSERT_TRUE(stream->Write(make_request(chunks[c], c)));
      ASSERT_TRUE(stream->Read(&response)) << "reply " << c;
      EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(400));
      EXPECT_TRUE(response.hits() == hit_bytes(serial_hits(chunks[c]))) << "chunk " << c;
    }
    stream->WritesDone();
    EXPECT_TRUE(stream->Finish().ok());
    EXPECT_EQ(last_stream_engine_calls(gathering->log(), "IntersectStream: 3 chunks"), 3);
  }
  EXPECT_EQ(gathering->stop(SIGTERM), 0) << gathering->log();
}

TEST_F(ServerApi, StreamGatherOutOfRangeIsRefused) {
  const SubprocessResult r = testing::run_outcore({"serve", store_, "--stream-gather-ms", "60001"},
                                                  std::chrono::milliseconds(30'000));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.stderr_text, "--stream-gather-ms")) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "60001")) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "60000")) << r.describe();
}

TEST_F(ServerApi, ClientCancellingMidStreamCostsOnlyItsOwnWork) {
  for (int round = 0; round < 3; ++round) {
    grpc::ClientContext context;
    auto stream = stub_->IntersectStream(&context);
    const std::vector<Ray> chunk = rays(5000, 30 + round);
    ASSERT_TRUE(stream->Write(make_request(chunk, 0)));
    v1::IntersectResponse response;
    ASSERT_TRUE(stream->Read(&response));
    for (uint64_t c = 1; c < 4; ++c) stream->Write(make_request(chunk, c));
    context.TryCancel();
    while (stream->Read(&response)) {
    }
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::CANCELLED);
    expect_serving();
  }
  // A stream abandoned without WritesDone or Finish (the context goes away).
  {
    grpc::ClientContext context;
    auto stream = stub_->OccludedStream(&context);
    const std::vector<Ray> chunk = rays(1000, 40);
    stream->Write(make_request(chunk, 0));
  }
  expect_serving();
}

// Separate servers: SIGTERM and SIGINT let an in-flight stream finish, then exit 0.
void expect_signal_drains(const std::string& store, int signal_number, const std::vector<Ray>& chunk,
                          const std::string& want) {
  std::string error;
  auto server = ServerProcess::start(store, {"--max-message-mb", "1"}, error);
  ASSERT_NE(server, nullptr) << error;
  auto channel = grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials());
  auto stub = v1::SceneQuery::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub->IntersectStream(&context);
  ASSERT_TRUE(stream->Write(make_request(chunk, 0)));
  v1::IntersectResponse response;
  ASSERT_TRUE(stream->Read(&response));  // the call is in flight on the server
  server->signal(signal_number);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  for (uint64_t c = 1; c < 4; ++c) ASSERT_TRUE(stream->Write(make_request(chunk, c))) << "chunk " << c;
  stream->WritesDone();
  int replies = 1;
  while (stream->Read(&response)) {
    EXPECT_TRUE(response.hits() == want);
    ++replies;
  }
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(replies, 4);
  EXPECT_EQ(server->stop(signal_number), 0) << server->log();
  EXPECT_TRUE(contains(server->log(), "draining")) << server->log();
  // New calls are refused once it is gone.
  grpc::ClientContext after;
  after.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  v1::SceneInfo info;
  EXPECT_FALSE(stub->GetSceneInfo(&after, v1::GetSceneInfoRequest(), &info).ok());
}

TEST_F(ServerApi, SigtermDrainsAnInFlightStreamAndExitsZero) {
  const std::vector<Ray> chunk = rays(2000, 50);
  expect_signal_drains(store_, SIGTERM, chunk, hit_bytes(serial_hits(chunk)));
}

TEST_F(ServerApi, SigintDrainsAnInFlightStreamAndExitsZero) {
  const std::vector<Ray> chunk = rays(2000, 51);
  expect_signal_drains(store_, SIGINT, chunk, hit_bytes(serial_hits(chunk)));
}

// The drain after SIGTERM is bounded: a batch still being traced when the
// bound passes is cancelled through the engine (the client gets an error, the
// log counts the request as cancelled and failed) and the process exits
// within the bound plus a little. The batch thrashes a small cache ray by ray
// (no_reorder), which takes far longer than the test.
TEST(ServerDrain, ABatchStillTracedWhenTheDrainBoundPassesIsCancelledAndTheServerExitsInTime) {
  TempDir dir;
  const std::string store = dir.file("scene");
  const SubprocessResult packed = testing::run_outcore(
      {"pack", "gen:sphere?level=6", "-o", store, "--brick-tris", "64", "-q", "--no-sync"},
      std::chrono::milliseconds(120'000));
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  constexpr double kDrainSeconds = 2;
  std::string error;
  auto server = ServerProcess::start(store, {"--cache-mb", "1", "--drain-s", "2", "--threads", "1"}, error);
  ASSERT_NE(server, nullptr) << error;
  auto opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok()) << opened.status().to_string();
  const std::vector<Ray> r = testing::make_test_rays((*opened)->manifest().bounds, 400'000, 8);
  v1::QueryRequest request = make_request(r);
  request.set_no_reorder(true);

  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(-1);
  arguments.SetMaxSendMessageSize(-1);
  auto stub = v1::SceneQuery::NewStub(
      grpc::CreateCustomChannel(server->address(), grpc::InsecureChannelCredentials(), arguments));
  grpc::Status long_call;
  std::thread caller([&] {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    v1::IntersectResponse response;
    long_call = stub->Intersect(&context, request, &response);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // the batch is being traced
  const auto signalled = std::chrono::steady_clock::now();
  const int exit_code = server->stop(SIGTERM, std::chrono::seconds(12));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
  caller.join();
  EXPECT_EQ(exit_code, 0) << server->log();
  EXPECT_LT(seconds, kDrainSeconds + 1.5) << server->log();
  EXPECT_FALSE(long_call.ok()) << "the cancelled batch was answered";
  const std::string log = server->log();
  EXPECT_TRUE(contains(log, "1 requests (1 failed, 1 cancelled)")) << log;
}

// `pack --force` may replace the store under a running server. The server
// goes on answering from the scene it opened (it holds its files open, so
// never a mix of both), and says so: one warning in its log and
// GetStats.store_changed, both naming the store.
TEST(ServerStoreReplaced, AServerWhoseStoreWasRepackedSaysSoAndKeepsServingTheSceneItOpened) {
  TempDir dir;
  const std::string store = dir.file("scene");
  const auto pack = [&](const std::string& input) {
    const SubprocessResult packed = testing::run_outcore(
        {"pack", input, "-o", store, "--force", "--brick-tris", "200", "-q", "--no-sync"},
        std::chrono::milliseconds(120'000));
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
  };
  pack("gen:sphere?level=3");
  std::string error;
  auto server = ServerProcess::start(store, {}, error);
  ASSERT_NE(server, nullptr) << error;
  auto opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok()) << opened.status().to_string();
  const std::vector<Ray> r = testing::make_test_rays((*opened)->manifest().bounds, 5000, 12);
  opened->reset();
  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  const auto query = [&] {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    v1::IntersectResponse response;
    const grpc::Status status = stub->Intersect(&context, make_request(r), &response);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response.hits();
  };
  const auto changed = [&] {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    v1::ServerStats stats;
    EXPECT_TRUE(stub->GetStats(&context, v1::GetStatsRequest(), &stats).ok());
    return stats.store_changed();
  };
  const std::string before = query();
  EXPECT_EQ(changed(), "");

  pack("gen:torus?major=0.7&minor=0.3");
  std::string why;
  for (int i = 0; i < 40 && why.empty(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    why = changed();
  }
  EXPECT_TRUE(contains(why, store)) << why;
  EXPECT_TRUE(contains(why, "replaced")) << why;
  EXPECT_TRUE(query() == before) << "the server answered from another scene than the one it opened";
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  EXPECT_TRUE(query() == before);
  const std::string log = server->log();
  EXPECT_EQ(testing::count_of(log, "was replaced"), 1u) << log;
  EXPECT_TRUE(contains(log, store)) << log;
  stub.reset();
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
