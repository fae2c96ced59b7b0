// Same-host shared payloads end to end against a real `outcore serve`: the
// C++ client's shared path answers as the engine does and falls back to bytes
// where the server refuses; malformed shared requests are named errors and
// the server keeps serving.
#include <arpa/inet.h>
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "client/cpp/scene_client.h"
#include "core/query/query_engine.h"
#include "core/util/shared_memory.h"
#include "outcore/v1/scene_query.grpc.pb.h"
#include "proto/outcore/v1/shared_payload_wire.h"
#include "server/shared_payload.h"
#include "tests/support/packed_scene.h"
#include "tests/support/server_process.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::ServerProcess;

constexpr uint64_t kHeader = SharedMemoryObject::kHeaderBytes;

std::string bytes_of(const void* data, std::size_t size) {
  return std::string(static_cast<const char*>(data), size);
}

v1::QueryRequest testing_shared_request(const SharedMemoryObject& object, uint64_t n) {
  v1::QueryRequest request;
  v1::RayBatch* batch = request.mutable_batch();
  batch->set_layout_version(1);
  batch->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  batch->set_ray_count(n);
  request.mutable_shared()->set_name(object.name());
  request.mutable_shared()->set_rays_offset(kHeader);
  request.mutable_shared()->set_answers_offset(kHeader + n * sizeof(Ray));
  request.mutable_shared()->set_token(object.token());
  return request;
}

bool carries_refusal(const grpc::ClientContext& context) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto [first, last] = trailers.equal_range(wire::kSharedRefusedKey);
  for (auto it = first; it != last; ++it) {
    if (std::string(it->second.data(), it->second.size()) == wire::kSharedRefusedValue) return true;
  }
  return false;
}

// The objects this process's C++ clients made that still exist.
int own_objects_left() {
  const std::string prefix = "outcore-cpp-" + std::to_string(getpid()) + "-";
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator("/dev/shm")) {
    if (entry.path().filename().string().starts_with(prefix)) ++count;
  }
  return count;
}

// A scene packed by the real packer and the engine over it, for the tests'
// servers and their serial answers; null (with a test failure) when either
// step fails.
struct ServedScene {
  std::unique_ptr<testing::PackedScene> packed;
  std::unique_ptr<QueryEngine> engine;

  static std::unique_ptr<ServedScene> pack(const std::vector<std::string>& inputs,
                                           uint32_t brick_triangles = 32768) {
    auto scene = std::make_unique<ServedScene>();
    scene->packed = testing::pack_test_scene(inputs, brick_triangles);
    auto engine = QueryEngine::open(scene->packed->path, EngineOptions{});
    EXPECT_TRUE(engine.ok()) << engine.status().to_string();
    if (!engine.ok()) return nullptr;
    scene->engine = std::move(*engine);
    return scene;
  }
  const std::string& store() const { return packed->path; }
};

class ServerSharedPayload : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = ServedScene::pack({"gen:sphere?level=3", "gen:torus?cx=3"}, 200).release();
    ASSERT_NE(scene_, nullptr);
    engine_ = scene_->engine.get();
    std::string error;
    server_ = ServerProcess::start(scene_->store(), {}, error).release();
    ASSERT_NE(server_, nullptr) << error;
  }
  static void TearDownTestSuite() {
    if (server_ != nullptr) {
      EXPECT_EQ(server_->stop(SIGTERM), 0) << server_->log();
    }
    delete server_;
    delete scene_;
    server_ = nullptr;
    engine_ = nullptr;
    scene_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(server_, nullptr) << "suite setup failed";
    stub_ =
        v1::SceneQuery::NewStub(grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
  }

  static std::vector<Ray> rays(std::size_t n, uint32_t seed) {
    return testing::make_test_rays(engine_->store().manifest().bounds, n, seed);
  }
  static std::vector<Hit> serial_hits(std::span<const Ray> r) {
    std::vector<Hit> hits(r.size());
    EXPECT_TRUE(engine_->intersect(r, hits, QueryOptions{}).ok());
    return hits;
  }

  // A request naming `object` with the rays after its header and the
  // answers after them.
  static v1::QueryRequest shared_request(const SharedMemoryObject& object, uint64_t n) {
    return testing_shared_request(object, n);
  }

  grpc::Status intersect(const v1::QueryRequest& request, v1::IntersectResponse* response,
                         bool* refused = nullptr) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    const grpc::Status status = stub_->Intersect(&context, request, response);
    if (refused != nullptr) *refused = carries_refusal(context);
    return status;
  }

  void expect_error(const v1::QueryRequest& request, grpc::StatusCode code, const std::string& part,
                    bool refusal = false) {
    v1::IntersectResponse response;
    bool refused = false;
    const grpc::Status status = intersect(request, &response, &refused);
    EXPECT_EQ(status.error_code(), code) << status.error_message();
    EXPECT_NE(status.error_message().find(part), std::string::npos)
        << "'" << part << "' not in: " << status.error_message();
    EXPECT_EQ(refused, refusal) << "the refusal marker on: " << status.error_message();
    // Still serving, through shared memory too.
    auto client = client::SceneClient::connect(server_->address());
    ASSERT_TRUE(client.ok()) << client.status().to_string();
    const std::vector<Ray> r = rays(client::kSharedMinRays, 77);
    std::vector<Hit> hits(r.size());
    client::CallStats stats;
    ASSERT_TRUE((*client)->intersect(r, hits, {}, &stats).ok());
    EXPECT_TRUE(stats.shared);
    EXPECT_EQ(bytes_of(hits.data(), hits.size() * sizeof(Hit)),
              bytes_of(serial_hits(r).data(), r.size() * sizeof(Hit)));
  }

  static ServedScene* scene_;
  static QueryEngine* engine_;
  static ServerProcess* server_;
  std::unique_ptr<v1::SceneQuery::Stub> stub_;
};

ServedScene* ServerSharedPayload::scene_ = nullptr;
QueryEngine* ServerSharedPayload::engine_ = nullptr;
ServerProcess* ServerSharedPayload::server_ = nullptr;

TEST_F(ServerSharedPayload, LargeBatchesGoThroughSharedMemoryAndAnswerAsTheEngine) {
  {
    auto client = client::SceneClient::connect(server_->address());
    ASSERT_TRUE(client.ok()) << client.status().to_string();
    EXPECT_TRUE((*client)->connected_scene().shared_payloads());
    for (const std::size_t n : {client::kSharedMinRays, std::size_t{50'000}, std::size_t{20'000}}) {
      const std::vector<Ray> r = rays(n, static_cast<uint32_t>(n));
      std::vector<Hit> hits(n);
      client::CallStats stats;
      ASSERT_TRUE((*client)->intersect(r, hits, {}, &stats).ok());
      EXPECT_TRUE(stats.shared) << n;
      EXPECT_EQ(stats.messages, 1u);
      EXPECT_EQ(stats.engine.rays(), n);
      EXPECT_EQ(bytes_of(hits.data(), n * sizeof(Hit)), bytes_of(serial_hits(r).data(), n * sizeof(Hit)))
          << n;

      std::vector<uint8_t> flags(n), want(n);
      ASSERT_TRUE(engine_->occluded(r, want, QueryOptions{}).ok());
      stats = {};
      ASSERT_TRUE((*client)->occluded(r, flags, {}, &stats).ok());
      EXPECT_TRUE(stats.shared);
      EXPECT_EQ(flags, want) << n;
    }
    // Below the threshold, or with explicit chunks: bytes.
    const std::vector<Ray> small = rays(client::kSharedMinRays - 1, 3);
    std::vector<Hit> hits(small.size());
    client::CallStats stats;
    ASSERT_TRUE((*client)->intersect(small, hits, {}, &stats).ok());
    EXPECT_FALSE(stats.shared);
    const std::vector<Ray> big = rays(40'000, 4);
    hits.resize(big.size());
    client::CallOptions chunked;
    chunked.chunk_rays = 10'000;
    stats = {};
    ASSERT_TRUE((*client)->intersect(big, hits, chunked, &stats).ok());
    EXPECT_FALSE(stats.shared);
    EXPECT_EQ(stats.messages, 4u);
    // Strict mode names the bad ray as in a unary bytes call.
    std::vector<Ray> bad = rays(30'000, 5);
    bad[21'234].direction.x = std::numeric_limits<float>::quiet_NaN();
    hits.resize(bad.size());
    client::CallOptions strict;
    strict.strict = true;
    const Status refused = (*client)->intersect(bad, hits, strict);
    EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(refused.message().find("ray 21234"), std::string::npos) << refused.message();
    // An error is not a refusal: the next batch still goes through shared memory.
    stats = {};
    ASSERT_TRUE((*client)->intersect(big, std::span<Hit>(hits).first(big.size()), {}, &stats).ok());
    EXPECT_TRUE(stats.shared);
    EXPECT_GT(own_objects_left(), 0);
  }
  EXPECT_EQ(own_objects_left(), 0) << "a destroyed client unlinks its objects";
}

TEST_F(ServerSharedPayload, MalformedSharedRequestsAreNamedErrorsAndTheServerKeepsServing) {
  const uint64_t n = 1000;
  const std::vector<Ray> r = rays(n, 11);
  const uint64_t object_bytes = kHeader + n * 64;
  auto object = SharedMemoryObject::create("cpp-" + std::to_string(getpid()) + "-test", object_bytes);
  ASSERT_TRUE(object.ok()) << object.status().to_string();
  std::memcpy(object->data() + kHeader, r.data(), n * sizeof(Ray));

  {  // The well-formed request, by hand: answers land in the object.
    v1::IntersectResponse response;
    const grpc::Status status = intersect(shared_request(*object, n), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(response.answers_in_shared());
    EXPECT_TRUE(response.hits().empty());
    EXPECT_EQ(bytes_of(object->data() + kHeader + n * sizeof(Ray), n * sizeof(Hit)),
              bytes_of(serial_hits(r).data(), n * sizeof(Hit)));
  }
  // Another object's token, or none: the name alone does not let anyone in.
  auto other = SharedMemoryObject::create("cpp-" + std::to_string(getpid()) + "-test", 4096);
  ASSERT_TRUE(other.ok());
  v1::QueryRequest wrong_token = shared_request(*object, n);
  wrong_token.mutable_shared()->set_token(other->token());
  expect_error(wrong_token, grpc::StatusCode::PERMISSION_DENIED, "token does not match");
  v1::QueryRequest no_token = shared_request(*object, n);
  no_token.mutable_shared()->clear_token();
  expect_error(no_token, grpc::StatusCode::PERMISSION_DENIED, "shared.token");
  EXPECT_EQ(bytes_of(object->data() + kHeader + n * sizeof(Ray), n * sizeof(Hit)),
            bytes_of(serial_hits(r).data(), n * sizeof(Hit)))
      << "refused calls wrote nothing";

  v1::QueryRequest in_header = shared_request(*object, n);
  in_header.mutable_shared()->set_rays_offset(8);
  expect_error(in_header, grpc::StatusCode::INVALID_ARGUMENT, "shared.rays_offset is 8, inside");
  v1::QueryRequest with_bytes = shared_request(*object, n);
  with_bytes.mutable_batch()->set_rays(std::string(n * sizeof(Ray), '\0'));
  expect_error(with_bytes, grpc::StatusCode::INVALID_ARGUMENT, "leave batch.rays empty");

  v1::QueryRequest overlapping = shared_request(*object, n);
  overlapping.mutable_shared()->set_answers_offset(kHeader + n * sizeof(Ray) - 32);
  expect_error(overlapping, grpc::StatusCode::INVALID_ARGUMENT, "overlap");

  v1::QueryRequest outside = shared_request(*object, n);
  outside.mutable_shared()->set_answers_offset(object_bytes - 10);
  expect_error(outside, grpc::StatusCode::INVALID_ARGUMENT, "are not inside " + object->name());

  v1::QueryRequest huge_offset = shared_request(*object, n);
  huge_offset.mutable_shared()->set_rays_offset(~uint64_t{0} - 100);
  expect_error(huge_offset, grpc::StatusCode::INVALID_ARGUMENT, "not inside");

  v1::QueryRequest bad_name = shared_request(*object, n);
  bad_name.mutable_shared()->set_name("/etc/passwd");
  expect_error(bad_name, grpc::StatusCode::INVALID_ARGUMENT, "shared.name");

  v1::QueryRequest missing = shared_request(*object, n);
  missing.mutable_shared()->set_name("/outcore-test-missing-object");
  expect_error(missing, grpc::StatusCode::FAILED_PRECONDITION, "no shared-memory object", /*refusal=*/true);

  v1::QueryRequest bad_layout = shared_request(*object, n);
  bad_layout.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_UNSPECIFIED);
  expect_error(bad_layout, grpc::StatusCode::INVALID_ARGUMENT, "batch.ray_layout");

  // Shrunk before the call: its ranges no longer fit.
  const int fd = shm_open(object->name().c_str(), O_RDWR, 0);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(ftruncate(fd, 4096), 0);
  close(fd);
  expect_error(shared_request(*object, n), grpc::StatusCode::INVALID_ARGUMENT, "are not inside");

  // A stream chunk may not carry one.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto stream = stub_->IntersectStream(&context);
  ASSERT_TRUE(stream->Write(shared_request(*object, n)));
  stream->WritesDone();
  v1::IntersectResponse ignored;
  while (stream->Read(&ignored)) {
  }
  const grpc::Status streamed = stream->Finish();
  EXPECT_EQ(streamed.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(streamed.error_message().find("not streams"), std::string::npos) << streamed.error_message();
}

TEST(ServerSharedPayloadOff, ANoSharedPayloadsServerRefusesThemAndClientsFallBackToBytes) {
  const std::unique_ptr<ServedScene> scene = ServedScene::pack({"gen:sphere?level=3"});
  ASSERT_NE(scene, nullptr);
  const std::unique_ptr<QueryEngine>& engine = scene->engine;
  std::string error;
  auto server = ServerProcess::start(scene->store(), {"--no-shared-payloads"}, error);
  ASSERT_NE(server, nullptr) << error;
  const std::vector<Ray> r = testing::make_test_rays(engine->store().manifest().bounds, 20'000, 9);
  std::vector<Hit> want(r.size());
  ASSERT_TRUE(engine->intersect(r, want, QueryOptions{}).ok());

  auto client = client::SceneClient::connect(server->address());
  ASSERT_TRUE(client.ok());
  EXPECT_FALSE((*client)->connected_scene().shared_payloads());
  std::vector<Hit> hits(r.size());
  client::CallStats stats;
  ASSERT_TRUE((*client)->intersect(r, hits, {}, &stats).ok());
  EXPECT_FALSE(stats.shared);
  EXPECT_EQ(bytes_of(hits.data(), hits.size() * sizeof(Hit)),
            bytes_of(want.data(), want.size() * sizeof(Hit)));

  // A client that sends one anyway is told why.
  auto object =
      SharedMemoryObject::create("cpp-" + std::to_string(getpid()) + "-test", kHeader + r.size() * 64);
  ASSERT_TRUE(object.ok());
  std::memcpy(object->data() + kHeader, r.data(), r.size() * sizeof(Ray));
  const v1::QueryRequest request = testing_shared_request(*object, r.size());
  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  v1::IntersectResponse response;
  const grpc::Status status = stub->Intersect(&context, request, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(status.error_message().find("--no-shared-payloads"), std::string::npos) << status.error_message();
  EXPECT_TRUE(carries_refusal(context)) << "a refusal tells clients to send bytes";
  // Channels closed first: gRPC's shutdown waits out its drain deadline for
  // connections still open.
  stub.reset();
  client->reset();
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

// Any local user can make /dev/shm/outcore-x a FIFO. Opening one for reading
// blocks until a writer comes: every such call would hold an RPC thread for
// ever, and with as many as --rpc-threads ordinary calls could not be served
// (here more such calls than the server's 4 threads).
// The server must refuse it at once, naming the object, and go on serving.
TEST(ServerSharedPayloadFifo, AFifoNamedAsAnObjectIsRefusedAtOnceAndOrdinaryQueriesGoOn) {
  const std::unique_ptr<ServedScene> scene = ServedScene::pack({"gen:sphere?level=3"});
  ASSERT_NE(scene, nullptr);
  std::string error;
  auto server = ServerProcess::start(scene->store(), {"--rpc-threads", "4"}, error);
  ASSERT_NE(server, nullptr) << error;
  const std::string name = "/outcore-test-fifo-" + std::to_string(getpid());
  const std::string path = "/dev/shm" + name;
  ::unlink(path.c_str());
  ASSERT_EQ(mkfifo(path.c_str(), 0600), 0) << std::strerror(errno);
  // Releases server threads a broken server left blocked in the FIFO, so that
  // it can still be stopped.
  const auto release_blocked_readers = [&] {
    const int writer = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
    if (writer >= 0) ::close(writer);
  };

  v1::QueryRequest request;
  request.mutable_batch()->set_layout_version(1);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  request.mutable_batch()->set_ray_count(1);
  request.mutable_shared()->set_name(name);
  request.mutable_shared()->set_rays_offset(kHeader);
  request.mutable_shared()->set_answers_offset(kHeader + sizeof(Ray));
  request.mutable_shared()->set_token(std::string(SharedMemoryObject::kTokenBytes, 'x'));
  auto stub =
      v1::SceneQuery::NewStub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  for (int call = 0; call < 6; ++call) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
    v1::IntersectResponse response;
    const grpc::Status status = stub->Intersect(&context, request, &response);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << "call " << call << ": " << status.error_message();
    EXPECT_NE(status.error_message().find(name), std::string::npos) << status.error_message();
    EXPECT_NE(status.error_message().find("FIFO"), std::string::npos) << status.error_message();
  }

  // Ordinary queries, in bytes and through shared memory, answer as the engine.
  const std::vector<Ray> r = testing::make_test_rays(scene->engine->store().manifest().bounds, 20'000, 5);
  std::vector<Hit> want(r.size());
  ASSERT_TRUE(scene->engine->intersect(r, want, QueryOptions{}).ok());
  client::ConnectOptions options;
  options.timeout_seconds = 5;
  auto client = client::SceneClient::connect(server->address(), options);
  const bool connected = client.ok();
  EXPECT_TRUE(connected) << client.status().to_string();
  if (connected) {
    client::CallOptions call;
    call.deadline_seconds = 5;
    for (const std::size_t n : {std::size_t{1000}, r.size()}) {
      std::vector<Hit> hits(n);
      const Status status = (*client)->intersect(std::span<const Ray>(r.data(), n), hits, call);
      EXPECT_TRUE(status.ok()) << status.to_string();
      EXPECT_TRUE(bytes_of(hits.data(), n * sizeof(Hit)) == bytes_of(want.data(), n * sizeof(Hit))) << n;
    }
    client->reset();
  }
  release_blocked_readers();
  ::unlink(path.c_str());
  stub.reset();
  EXPECT_EQ(server->stop(SIGTERM, std::chrono::seconds(15)), 0) << server->log();
}

TEST(LoopbackTarget, OnlyThisHostsAddressesCount) {
  // The same list as tests/python/test_shared.py's, so both clients agree.
  for (const char* local :
       {"127.0.0.1:50051", "localhost:1", "LocalHost:1", "localhost.:1", "127.1.2.3:9", "[::1]:50051",
        "unix:/tmp/s", "unix-abstract:s", "ipv4:127.0.0.1:5", "ipv4:127.0.0.1:5,127.0.0.2:6", "ipv6:[::1]:5",
        "dns:///localhost:5", "dns:localhost:5", "dns://8.8.8.8/localhost:5", "[::ffff:127.0.0.1]:7", "::1",
        "localhost"}) {
    EXPECT_TRUE(client::is_loopback_target(local)) << local;
  }
  for (const char* remote :
       {"10.0.0.1:50051", "example.com:1", "[2001:db8::1]:5", "128.0.0.1:5", "localhost.example.com:5",
        "[::1", "ipv4:127.0.0.1:5,10.0.0.1:6", "[::ffff:10.0.0.1]:7", "dns://8.8.8.8:53", ""}) {
    EXPECT_FALSE(client::is_loopback_target(remote)) << remote;
  }
}

TEST(LoopbackPeer, TheServerAcceptsOnlyLoopbackPeers) {
  // gRPC 1.51 writes IPv6 peers with escaped brackets ("ipv6:%5B::1%5D:4")
  // and IPv4-mapped ones as ipv4; the other forms are accepted too.
  for (const char* local :
       {"ipv4:127.0.0.1:50051", "ipv4:127.9.8.7:1", "ipv6:%5B::1%5D:4", "ipv6:[::1]:4",
        "ipv6:%5B::ffff:127.0.0.1%5D:4", "ipv6:[::ffff:127.0.0.1]:4", "unix:/tmp/x", "unix-abstract:x"}) {
    EXPECT_TRUE(server::is_loopback_peer(local)) << local;
  }
  for (const char* remote :
       {"ipv4:10.0.0.2:50051", "ipv6:%5B2001:db8::1%5D:4", "ipv6:[::1234]:4", "ipv4:1.127.0.0:1",
        "ipv6:%5B::ffff:10.0.0.1%5D:4", "ipv6:%5Bfe80::1%25eth0%5D:4", "ipv4:127.0.0.1.example:1",
        "ipv4:", "", "tcp:127.0.0.1:1"}) {
    EXPECT_FALSE(server::is_loopback_peer(remote)) << remote;
  }
}

bool ipv6_loopback_available() {
  const int fd = socket(AF_INET6, SOCK_STREAM, 0);
  if (fd < 0) return false;
  sockaddr_in6 address{};
  address.sin6_family = AF_INET6;
  address.sin6_addr = in6addr_loopback;
  const bool bound = bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
  close(fd);
  return bound;
}

TEST(ServerSharedPayloadIpv6, AClientOnIpv6LoopbackGoesThroughSharedMemory) {
  if (!ipv6_loopback_available()) GTEST_SKIP() << "this host has no IPv6 loopback";
  const std::unique_ptr<ServedScene> scene = ServedScene::pack({"gen:sphere?level=3"});
  ASSERT_NE(scene, nullptr);
  const std::unique_ptr<QueryEngine>& engine = scene->engine;
  std::string error;
  auto server = ServerProcess::start(scene->store(), {"--listen", "[::1]:0"}, error);
  ASSERT_NE(server, nullptr) << error;
  ASSERT_TRUE(server->address().starts_with("[::1]:")) << server->address();
  const std::vector<Ray> r = testing::make_test_rays(engine->store().manifest().bounds, 20'000, 13);
  std::vector<Hit> want(r.size());
  ASSERT_TRUE(engine->intersect(r, want, QueryOptions{}).ok());
  auto client = client::SceneClient::connect(server->address());
  ASSERT_TRUE(client.ok()) << client.status().to_string();
  std::vector<Hit> hits(r.size());
  for (int call = 0; call < 2; ++call) {  // the second shows the first did not switch shared memory off
    client::CallStats stats;
    ASSERT_TRUE((*client)->intersect(r, hits, {}, &stats).ok());
    EXPECT_TRUE(stats.shared) << "call " << call;
    EXPECT_EQ(bytes_of(hits.data(), hits.size() * sizeof(Hit)),
              bytes_of(want.data(), want.size() * sizeof(Hit)));
  }
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

TEST_F(ServerSharedPayload, BatchesLargerThanOneGroupAnswerAsTheEngineAndNameBadRaysByTheirIndex) {
  // More than server::kSharedGroupRays rays: traced in two groups.
  const uint64_t n = server::kSharedGroupRays + 1000;
  const std::vector<Ray> r = rays(n, 17);
  auto client = client::SceneClient::connect(server_->address());
  ASSERT_TRUE(client.ok());
  std::vector<uint8_t> flags(n), want(n);
  ASSERT_TRUE(engine_->occluded(r, want, QueryOptions{}).ok());
  client::CallStats stats;
  ASSERT_TRUE((*client)->occluded(r, flags, {}, &stats).ok());
  EXPECT_TRUE(stats.shared);
  EXPECT_EQ(stats.messages, 1u);
  EXPECT_EQ(stats.engine.rays(), n) << "the groups' figures are summed";
  EXPECT_EQ(flags, want);

  std::vector<Ray> bad = r;
  bad[server::kSharedGroupRays + 7].tnear = -1.0f;
  client::CallOptions strict;
  strict.strict = true;
  const Status refused = (*client)->occluded(bad, flags, strict);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("ray " + std::to_string(server::kSharedGroupRays + 7) + ":"),
            std::string::npos)
      << refused.message();
}

// CountIntersections through a shared payload: the counts (4 bytes a ray)
// land in the object, equal to the engine's; a token of another object is
// PERMISSION_DENIED. ListIntersections likewise, within shared.answers_bytes.
TEST_F(ServerSharedPayload, CountsThroughSharedMemoryEqualTheEngines) {
  const uint64_t n = 3000;
  const std::vector<Ray> r = rays(n, 31);
  constexpr uint64_t kBytesPerRay = 256;  // a ray, then room for its counts and hits
  auto object =
      SharedMemoryObject::create("cpp-" + std::to_string(getpid()) + "-test", kHeader + n * kBytesPerRay);
  ASSERT_TRUE(object.ok()) << object.status().to_string();
  std::memcpy(object->data() + kHeader, r.data(), n * sizeof(Ray));
  std::vector<uint32_t> expected(n, 0);
  ASSERT_TRUE(engine_->all_hits(r, expected, nullptr, QueryOptions{}).ok());
  uint64_t total = 0;
  for (const uint32_t c : expected) total += c;
  ASSERT_GT(total, n / 10) << "the rays must hit something for the test to mean anything";

  const v1::QueryRequest request = shared_request(*object, n);
  {
    grpc::ClientContext context;
    v1::CountResponse response;
    const grpc::Status status = stub_->CountIntersections(&context, request, &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_TRUE(response.answers_in_shared());
    EXPECT_TRUE(response.counts().empty());
    EXPECT_EQ(response.ray_count(), n);
    EXPECT_EQ(response.stats().rays(), n);
    EXPECT_EQ(bytes_of(object->data() + kHeader + n * sizeof(Ray), n * sizeof(uint32_t)),
              bytes_of(expected.data(), n * sizeof(uint32_t)));
  }
  {
    auto other = SharedMemoryObject::create("cpp-" + std::to_string(getpid()) + "-test", 4096);
    ASSERT_TRUE(other.ok());
    v1::QueryRequest wrong_token = request;
    wrong_token.mutable_shared()->set_token(other->token());
    grpc::ClientContext context;
    v1::CountResponse response;
    const grpc::Status status = stub_->CountIntersections(&context, wrong_token, &response);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::PERMISSION_DENIED) << status.error_message();
  }
  {  // The C++ client's counts of a large batch take the same path.
    auto client = client::SceneClient::connect(server_->address());
    ASSERT_TRUE(client.ok()) << client.status().to_string();
    const std::vector<Ray> many = rays(client::kSharedMinRays + 100, 32);
    std::vector<uint32_t> want(many.size(), 0), got(many.size(), 0), by_bytes(many.size(), 0);
    ASSERT_TRUE(engine_->all_hits(many, want, nullptr, QueryOptions{}).ok());
    client::CallStats stats;
    ASSERT_TRUE((*client)->count_intersections(many, got, {}, &stats).ok());
    EXPECT_TRUE(stats.shared);
    EXPECT_EQ(got, want);
    client::CallOptions chunked;
    chunked.chunk_rays = 5000;  // chunked calls go as bytes
    client::CallStats bytes_stats;
    ASSERT_TRUE((*client)->count_intersections(many, by_bytes, chunked, &bytes_stats).ok());
    EXPECT_FALSE(bytes_stats.shared);
    EXPECT_EQ(by_bytes, want);
  }
  // ListIntersections: its room must be named; counts then hits land in the
  // object when they fit, in the reply's fields when they do not.
  std::vector<uint32_t> counts(n, 0);
  std::vector<RayHitRecord> records;
  ASSERT_TRUE(engine_->all_hits(r, counts, &records, QueryOptions{}).ok());
  std::string want_hits;
  for (const RayHitRecord& record : records) want_hits += bytes_of(&record.hit, sizeof(Hit));
  const auto list = [&](uint64_t room, v1::ListResponse* response) {
    v1::QueryRequest listing = request;
    listing.mutable_shared()->set_answers_bytes(room);
    grpc::ClientContext context;
    return stub_->ListIntersections(&context, listing, response);
  };
  {
    v1::ListResponse response;
    const grpc::Status status = list(0, &response);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(status.error_message().find("answers_bytes"), std::string::npos) << status.error_message();
  }
  {
    v1::ListResponse response;
    const grpc::Status status = list(n * (kBytesPerRay - sizeof(Ray)), &response);  // the rest of the object
    ASSERT_TRUE(status.ok()) << status.error_message();
    ASSERT_TRUE(response.answers_in_shared());
    EXPECT_TRUE(response.counts().empty() && response.hits().empty());
    EXPECT_EQ(response.hit_count(), records.size());
    const char* answers = object->data() + kHeader + n * sizeof(Ray);
    EXPECT_EQ(bytes_of(answers, n * sizeof(uint32_t)), bytes_of(counts.data(), n * sizeof(uint32_t)));
    EXPECT_EQ(bytes_of(answers + n * sizeof(uint32_t), want_hits.size()), want_hits);
  }
  {
    v1::ListResponse response;
    const grpc::Status status = list(n * sizeof(uint32_t), &response);  // room for the counts only
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_FALSE(response.answers_in_shared());
    EXPECT_EQ(response.counts(), bytes_of(counts.data(), n * sizeof(uint32_t)));
    EXPECT_EQ(response.hits(), want_hits);
  }
  {
    v1::ListResponse response;
    const grpc::Status status = list(n * kBytesPerRay, &response);  // past the object's end
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
