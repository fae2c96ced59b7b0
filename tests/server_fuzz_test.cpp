// Randomized malformed requests thrown at the SceneQuery handlers, served
// in-process by a real grpc::Server on a loopback port: random bytes and
// mutated encodings sent raw (GenericStub), random field values, byte lengths
// and NaN/Inf rays, oversize messages, and streams cut short (cancelled,
// abandoned, bad chunk in the middle). Nothing may crash or leak (the suite
// also runs under ASan/UBSan); every reply is OK with the in-process engine's
// answer, or a non-OK status with a message; well-formed requests always
// succeed and malformed ones are INVALID_ARGUMENT naming the field or ray.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <future>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/query/query_engine.h"
#include "server/ray_batch.h"
#include "server/scene_query_service.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr int kRounds = 1200;
#else
constexpr int kRounds = 4000;
#endif
constexpr uint64_t kMaxMessageBytes = 256 << 10;

class ServerFuzz : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    const std::string store = dir_->file("scene");
    const auto packed = testing::run_outcore({"pack", "gen:sphere?level=2", "gen:torus?cx=3", "-o", store,
                                              "--brick-tris", "100", "-q", "--no-sync"},
                                             std::chrono::milliseconds(120'000));
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    EngineOptions options;
    options.cache_bytes = 64 << 20;
    auto engine = QueryEngine::open(store, options);
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    engine_ = engine->release();
    server::ServiceOptions service_options;
    service_options.max_message_bytes = kMaxMessageBytes;
    service_ = new server::SceneQueryService(*engine_, service_options);
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    builder.SetMaxReceiveMessageSize(static_cast<int>(kMaxMessageBytes));
    builder.SetMaxSendMessageSize(static_cast<int>(kMaxMessageBytes));
    builder.RegisterService(service_);
    server_ = builder.BuildAndStart().release();
    ASSERT_NE(server_, nullptr);
    ASSERT_NE(port, 0);
    address_ = new std::string("127.0.0.1:" + std::to_string(port));
  }
  static void TearDownTestSuite() {
    if (server_ != nullptr) {
      server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(10));
      server_->Wait();
    }
    delete server_;
    delete service_;
    delete engine_;
    delete address_;
    delete dir_;
    server_ = nullptr;
    service_ = nullptr;
    engine_ = nullptr;
    address_ = nullptr;
    dir_ = nullptr;
  }

  void SetUp() override {
    ASSERT_NE(server_, nullptr) << "suite setup failed";
    grpc::ChannelArguments arguments;
    arguments.SetMaxReceiveMessageSize(-1);
    arguments.SetMaxSendMessageSize(-1);
    channel_ = grpc::CreateCustomChannel(*address_, grpc::InsecureChannelCredentials(), arguments);
    stub_ = v1::SceneQuery::NewStub(channel_);
    generic_ = std::make_unique<grpc::GenericStub>(channel_);
  }

  static std::unique_ptr<grpc::ClientContext> context() {
    auto c = std::make_unique<grpc::ClientContext>();
    c->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    return c;
  }

  grpc::Status raw_call(const std::string& method, const std::string& bytes) {
    grpc::Slice slice(bytes);
    grpc::ByteBuffer request(&slice, 1);
    grpc::ByteBuffer response;
    auto c = context();
    std::promise<grpc::Status> done;
    generic_->UnaryCall(c.get(), method, grpc::StubOptions(), &request, &response,
                        [&done](grpc::Status s) { done.set_value(std::move(s)); });
    return done.get_future().get();
  }

  static testing::TempDir* dir_;
  static QueryEngine* engine_;
  static server::SceneQueryService* service_;
  static grpc::Server* server_;
  static std::string* address_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SceneQuery::Stub> stub_;
  std::unique_ptr<grpc::GenericStub> generic_;
};

testing::TempDir* ServerFuzz::dir_ = nullptr;
QueryEngine* ServerFuzz::engine_ = nullptr;
server::SceneQueryService* ServerFuzz::service_ = nullptr;
grpc::Server* ServerFuzz::server_ = nullptr;
std::string* ServerFuzz::address_ = nullptr;

// A random request and what the server must make of it.
struct Generated {
  v1::QueryRequest request;
  bool well_formed = false;    // version, layout, byte length and count agree
  bool bytes_intact = false;   // rays are exactly `rays` (answer comparable)
  int64_t first_invalid = -1;  // first ray ray_problem() rejects
  std::vector<Ray> rays;
};

Generated generate(std::mt19937_64& rng, const Aabb& bounds) {
  Generated g;
  auto pick = [&](uint64_t n) { return rng() % n; };
  size_t n = pick(10) == 0 ? pick(3000) : pick(200);
  bool huge_six = false;
  if (pick(60) == 0) {  // six-float rays that fit, whose hits do not
    n = 9000;
    huge_six = true;
  }
  int layout = v1::RAY_LAYOUT_F32X8;
  const uint64_t layout_roll = pick(10);
  if (huge_six || layout_roll == 6 || layout_roll == 7) layout = v1::RAY_LAYOUT_F32X6;
  if (!huge_six && layout_roll == 8) layout = v1::RAY_LAYOUT_UNSPECIFIED;
  if (!huge_six && layout_roll == 9) layout = 3 + static_cast<int>(pick(1000));
  uint32_t version = 1;
  if (pick(12) == 0) version = pick(2) ? 0 : 2 + static_cast<uint32_t>(pick(1u << 20));

  g.rays = testing::make_test_rays(bounds, n, static_cast<uint32_t>(rng()));
  const float poison[] = {std::numeric_limits<float>::quiet_NaN(),
                          std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity(),
                          3e38f,
                          -1.0f,
                          0.0f,
                          1e-42f};
  const bool poisoned = pick(3) == 0;
  for (Ray& ray : g.rays) {
    if (layout == v1::RAY_LAYOUT_F32X6) {
      ray.tnear = 0;
      ray.tfar = std::numeric_limits<float>::infinity();
    }
    if (poisoned && pick(30) == 0) {
      float* f = reinterpret_cast<float*>(&ray);
      const size_t components = layout == v1::RAY_LAYOUT_F32X6 ? 6 : 8;
      f[pick(components)] = poison[pick(std::size(poison))];
      if (pick(4) == 0) ray.direction = Vec3f(0, 0, 0);
    }
  }
  std::string bytes;
  const size_t ray_bytes = layout == v1::RAY_LAYOUT_F32X6 ? 24 : 32;
  for (const Ray& ray : g.rays) bytes.append(reinterpret_cast<const char*>(&ray), ray_bytes);
  g.bytes_intact = true;
  if (pick(8) == 0) {
    g.bytes_intact = false;
    const size_t delta = 1 + pick(40);
    if (pick(2) && bytes.size() >= delta) {
      bytes.resize(bytes.size() - delta);
    } else {
      for (size_t i = 0; i < delta; ++i) bytes.push_back(static_cast<char>(rng()));
    }
  }
  uint64_t count = bytes.size() / ray_bytes;
  if (pick(8) == 0) count = pick(n + 5);
  if (pick(200) == 0) count = rng();

  v1::RayBatch* batch = g.request.mutable_batch();
  batch->set_layout_version(version);
  batch->set_ray_layout(static_cast<v1::RayLayout>(layout));
  batch->set_ray_count(count);
  batch->set_rays(bytes);
  g.request.set_strict(pick(3) == 0);
  g.request.set_no_reorder(pick(4) == 0);
  g.request.set_sequence(rng());

  const uint32_t size = server::ray_layout_bytes(layout);
  g.well_formed = version == 1 && size != 0 && bytes.size() % size == 0 && count == bytes.size() / size;
  if (g.well_formed && g.bytes_intact) {
    for (size_t i = 0; i < g.rays.size() && g.first_invalid < 0; ++i) {
      if (ray_problem(g.rays[i])) g.first_invalid = static_cast<int64_t>(i);
    }
  }
  return g;
}

// Checks one answer against what the request deserves; `any_hit` picks the
// kind; `where` prefixes failure messages.
void check_answer(const Generated& g, const grpc::Status& status, const std::string& payload, bool any_hit,
                  QueryEngine& engine, const std::string& where) {
  const bool reply_too_large =
      g.well_formed && g.request.batch().ray_count() * (any_hit ? 1 : sizeof(Hit)) + 512 > kMaxMessageBytes;
  if (status.ok()) {
    ASSERT_TRUE(g.well_formed) << where << ": a malformed batch was answered";
    ASSERT_FALSE(reply_too_large) << where;
    if (!g.bytes_intact) return;
    ASSERT_FALSE(g.request.strict() && g.first_invalid >= 0)
        << where << ": strict let an invalid ray through";
    QueryOptions options;
    if (any_hit) {
      std::vector<uint8_t> want(g.rays.size());
      ASSERT_TRUE(engine.occluded(g.rays, want, options).ok());
      ASSERT_TRUE(payload == std::string(want.begin(), want.end())) << where << ": wrong any-hit answer";
    } else {
      std::vector<Hit> want(g.rays.size());
      ASSERT_TRUE(engine.intersect(g.rays, want, options).ok());
      ASSERT_TRUE(payload ==
                  std::string(reinterpret_cast<const char*>(want.data()), want.size() * sizeof(Hit)))
          << where << ": wrong hits";
    }
    return;
  }
  ASSERT_FALSE(status.error_message().empty()) << where << ": error without a message";
  if (!g.well_formed) {
    ASSERT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << where << ": " << status.error_message();
    ASSERT_TRUE(contains(status.error_message(), "batch.")) << where << ": " << status.error_message();
  } else if (reply_too_large || g.request.ByteSizeLong() > kMaxMessageBytes) {
    ASSERT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
        << where << ": " << status.error_message();
  } else {
    ASSERT_TRUE(!g.bytes_intact || (g.request.strict() && g.first_invalid >= 0))
        << where << ": a well-formed batch failed: " << status.error_message();
    ASSERT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << where;
    ASSERT_TRUE(contains(status.error_message(), "ray ")) << where << ": " << status.error_message();
  }
}

TEST_F(ServerFuzz, MalformedRequestsGetNamedErrorsAndNeverHurtTheServer) {
  std::mt19937_64 rng(20240607);
  const Aabb bounds = engine_->store().manifest().bounds;
  int answered = 0, refused = 0;
  for (int round = 0; round < kRounds; ++round) {
    const std::string where = "round " + std::to_string(round);
    const bool any_hit = rng() % 2;
    const uint64_t kind = rng() % 20;
    if (kind == 0) {  // random bytes
      std::string bytes(rng() % 600, '\0');
      for (char& c : bytes) c = static_cast<char>(rng());
      const grpc::Status status =
          raw_call(any_hit ? "/outcore.v1.SceneQuery/Occluded" : "/outcore.v1.SceneQuery/Intersect", bytes);
      (status.ok() ? answered : refused)++;
      continue;
    }
    if (kind == 1) {  // a valid encoding, mutated or truncated
      std::string bytes = generate(rng, bounds).request.SerializeAsString();
      if (!bytes.empty()) {
        if (rng() % 2) {
          bytes.resize(rng() % bytes.size());
        } else {
          for (int i = 0; i < 4; ++i) bytes[rng() % bytes.size()] = static_cast<char>(rng());
        }
      }
      const grpc::Status status = raw_call(
          any_hit ? "/outcore.v1.SceneQuery/OccludedStream" : "/outcore.v1.SceneQuery/Intersect", bytes);
      (status.ok() ? answered : refused)++;
      continue;
    }
    if (kind == 2) {  // a stream of random chunks, ping-pong, cut short in one of three ways
      auto c = context();
      const int chunks = 1 + static_cast<int>(rng() % 5);
      const int ending = static_cast<int>(rng() % 3);  // 0 WritesDone, 1 cancel, 2 abandon
      if (any_hit) {
        auto stream = stub_->OccludedStream(c.get());
        v1::OccludedResponse response;
        for (int k = 0; k < chunks; ++k) {
          const Generated g = generate(rng, bounds);
          if (!stream->Write(g.request)) break;
          if (!stream->Read(&response)) break;
          ASSERT_EQ(response.sequence(), g.request.sequence()) << where;
          check_answer(g, grpc::Status::OK, response.occluded(), true, *engine_,
                       where + " chunk " + std::to_string(k));
        }
        if (ending == 0) stream->WritesDone();
        if (ending != 2) {
          if (ending == 1) c->TryCancel();
          while (stream->Read(&response)) {
          }
          const grpc::Status status = stream->Finish();
          (status.ok() ? answered : refused)++;
        } else {
          c->TryCancel();
        }
      } else {
        auto stream = stub_->IntersectStream(c.get());
        v1::IntersectResponse response;
        for (int k = 0; k < chunks; ++k) {
          const Generated g = generate(rng, bounds);
          if (!stream->Write(g.request)) break;
          if (!stream->Read(&response)) {
            // The server ended the stream: this chunk was refused, with its name.
            if (ending == 2) break;
            stream->WritesDone();
            const grpc::Status status = stream->Finish();
            check_answer(g, status, "", false, *engine_, where + " chunk " + std::to_string(k));
            ASSERT_TRUE(contains(status.error_message(), "chunk " + std::to_string(k)) ||
                        status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED)
                << where << ": " << status.error_message();
            ++refused;
            goto next_round;
          }
          ASSERT_EQ(response.sequence(), g.request.sequence()) << where;
          check_answer(g, grpc::Status::OK, response.hits(), false, *engine_,
                       where + " chunk " + std::to_string(k));
        }
        if (ending == 0) stream->WritesDone();
        if (ending != 2) {
          if (ending == 1) c->TryCancel();
          while (stream->Read(&response)) {
          }
          const grpc::Status status = stream->Finish();
          (status.ok() ? answered : refused)++;
        } else {
          c->TryCancel();
        }
      }
      continue;
    }
    {  // one structured random request, unary
      const Generated g = generate(rng, bounds);
      auto c = context();
      grpc::Status status;
      std::string payload;
      if (any_hit) {
        v1::OccludedResponse response;
        status = stub_->Occluded(c.get(), g.request, &response);
        payload = response.occluded();
        if (status.ok()) {
          ASSERT_EQ(response.ray_count(), g.request.batch().ray_count()) << where;
        }
      } else {
        v1::IntersectResponse response;
        status = stub_->Intersect(c.get(), g.request, &response);
        payload = response.hits();
        if (status.ok()) {
          ASSERT_EQ(response.sequence(), g.request.sequence()) << where;
        }
      }
      check_answer(g, status, payload, any_hit, *engine_, where);
      (status.ok() ? answered : refused)++;
    }
  next_round:;
  }
  EXPECT_GT(answered, kRounds / 4);
  EXPECT_GT(refused, kRounds / 10);

  // Still serving, and every call was counted.
  const std::vector<Ray> rays = testing::make_test_rays(bounds, 1000, 7);
  v1::QueryRequest request;
  request.mutable_batch()->set_layout_version(1);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  request.mutable_batch()->set_ray_count(rays.size());
  request.mutable_batch()->set_rays(reinterpret_cast<const char*>(rays.data()), rays.size() * sizeof(Ray));
  v1::IntersectResponse response;
  auto c = context();
  ASSERT_TRUE(stub_->Intersect(c.get(), request, &response).ok());
  std::vector<Hit> want(rays.size());
  ASSERT_TRUE(engine_->intersect(rays, want, QueryOptions{}).ok());
  EXPECT_TRUE(response.hits() ==
              std::string(reinterpret_cast<const char*>(want.data()), want.size() * sizeof(Hit)));
  const server::ServiceCounters counters = service_->counters();
  EXPECT_GT(counters.failed_requests, 0u);
  EXPECT_GT(counters.requests, counters.failed_requests);
}

// Bytes that do not parse are the client's error, and it is told which
// message they were meant to be (gRPC's own answer is INTERNAL, no message).
TEST_F(ServerFuzz, BytesThatAreNoQueryRequestAreInvalidArgumentNamingTheMessage) {
  const std::vector<std::string> garbage = {
      std::string("\x0f", 1),   // field 1 with wire type 7
      std::string(11, '\xff'),  // a varint tag longer than ten bytes
      std::string("\x0a\x10"
                  "ab",
                  4),                         // batch: 16 bytes announced, 2 sent
      std::string("\x0a\x03\x08\x80\x80", 5)  // batch.layout_version: a varint cut short
  };
  // A stream's chunk likewise, named by its number (gRPC's typed reader took
  // it for the end of the stream, which then ended OK with it unanswered).
  for (const char* method :
       {"/outcore.v1.SceneQuery/Intersect", "/outcore.v1.SceneQuery/Occluded",
        "/outcore.v1.SceneQuery/IntersectStream", "/outcore.v1.SceneQuery/OccludedStream"}) {
    for (std::size_t i = 0; i < garbage.size(); ++i) {
      const grpc::Status status = raw_call(method, garbage[i]);
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
          << method << " garbage " << i << ": " << status.error_message();
      EXPECT_TRUE(contains(status.error_message(), "could not be parsed as outcore.v1.QueryRequest"))
          << method << " garbage " << i << ": '" << status.error_message() << "'";
      if (contains(method, "Stream")) {
        EXPECT_TRUE(contains(status.error_message(), "chunk 0")) << status.error_message();
      }
    }
  }
  // A well-formed request still gets its answer.
  const std::vector<Ray> rays = testing::make_test_rays(engine_->store().manifest().bounds, 64, 3);
  v1::QueryRequest request;
  request.mutable_batch()->set_layout_version(1);
  request.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X8);
  request.mutable_batch()->set_ray_count(rays.size());
  request.mutable_batch()->set_rays(reinterpret_cast<const char*>(rays.data()), rays.size() * sizeof(Ray));
  const grpc::Status status = raw_call("/outcore.v1.SceneQuery/Intersect", request.SerializeAsString());
  EXPECT_TRUE(status.ok()) << status.error_message();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
