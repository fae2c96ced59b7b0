// End-to-end tests of `outcore query` against a real `outcore serve` on a
// loopback port: the hits (and any-hit bools) files are bitwise the files
// `outcore trace` writes on the same store, for unary batches and for batches
// several times the server's max message size (streamed in chunks), on a
// generated scene and on the Stanford bunny; `query --stats` prints the
// engine's figures as `trace --stats` does, the same ones for the same rays;
// bad query arguments and an unreachable server are errors that name what is
// wrong.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <fstream>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "core/store/scene_store.h"
#include "tests/support/server_process.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::contains;
using testing::ServerProcess;
using testing::SubprocessResult;
using testing::TempDir;

constexpr std::size_t kSmallBatch = 3000;
// 3.2 MB of rays against a 1 MiB message limit: four chunks.
constexpr std::size_t kBigBatch = 100'000;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(120'000));
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return std::move(s).str();
}

struct Scene {
  std::string store;
  std::string small_rays;
  std::string big_rays;
  std::unique_ptr<ServerProcess> server;
};

class ServerE2e : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    gen_ = new Scene();
    bunny_ = new Scene();
    prepare(*gen_, "gen", {"gen:sphere?level=3", "gen:torus?cx=3", "--brick-tris", "200"});
    prepare(*bunny_, "bunny", {testing::model_path("stanford-bunny.obj"), "--brick-tris", "8000"});
  }
  static void TearDownTestSuite() {
    delete gen_;
    delete bunny_;
    delete dir_;
    gen_ = bunny_ = nullptr;
    dir_ = nullptr;
  }

  static void prepare(Scene& scene, const std::string& name, std::vector<std::string> pack_args) {
    scene.store = dir_->file(name);
    pack_args.insert(pack_args.begin(), "pack");
    for (const char* a : {"-o", "", "-q", "--no-sync"}) pack_args.push_back(a);
    pack_args[pack_args.size() - 3] = scene.store;
    const SubprocessResult packed = outcore(pack_args);
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    auto store = SceneStore::open(scene.store);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    const Aabb bounds = (*store)->manifest().bounds;
    scene.small_rays = dir_->file(name + "-small.npy");
    scene.big_rays = dir_->file(name + "-big.npy");
    ASSERT_TRUE(write_rays_npy(scene.small_rays, testing::make_test_rays(bounds, kSmallBatch, 11)).ok());
    ASSERT_TRUE(write_rays_npy(scene.big_rays, testing::make_test_rays(bounds, kBigBatch, 12)).ok());
    std::string error;
    scene.server = ServerProcess::start(scene.store, {"--max-message-mb", "1"}, error);
    ASSERT_NE(scene.server, nullptr) << error;
  }

  void SetUp() override {
    ASSERT_NE(gen_, nullptr);
    ASSERT_NE(gen_->server, nullptr) << "suite setup failed";
    ASSERT_NE(bunny_->server, nullptr) << "suite setup failed";
  }

  // Runs trace and query on the same rays and compares the files byte for byte;
  // returns query's stdout.
  static std::string expect_query_equals_trace(const Scene& scene, const std::string& rays, bool any_hit,
                                               std::vector<std::string> query_extra = {}) {
    static int counter = 0;
    const std::string tag = std::to_string(counter++);
    const std::string traced = dir_->file("trace-" + tag + ".npy");
    const std::string queried = dir_->file("query-" + tag + ".npy");
    std::vector<std::string> trace_args{"trace", scene.store, "--rays", rays, "-o", traced};
    std::vector<std::string> query_args{"query", "--server", scene.server->address(), "--rays", rays, "-o",
                                        queried, "--stats"};
    if (any_hit) {
      trace_args.push_back("--any-hit");
      query_args.push_back("--any-hit");
    }
    query_args.insert(query_args.end(), query_extra.begin(), query_extra.end());
    const SubprocessResult t = outcore(trace_args);
    EXPECT_TRUE(t.succeeded()) << t.describe();
    const SubprocessResult q = outcore(query_args);
    EXPECT_TRUE(q.succeeded()) << q.describe() << "\nserver log:\n" << scene.server->log();
    const std::string want = read_bytes(traced);
    EXPECT_GT(want.size(), 128u);
    EXPECT_TRUE(read_bytes(queried) == want)
        << "query's " << (any_hit ? "bools" : "hits") << " differ from trace's for " << rays;
    return q.stdout_text;
  }

  static TempDir* dir_;
  static Scene* gen_;
  static Scene* bunny_;
};

TempDir* ServerE2e::dir_ = nullptr;
Scene* ServerE2e::gen_ = nullptr;
Scene* ServerE2e::bunny_ = nullptr;

TEST_F(ServerE2e, UnaryClosestHitsEqualTraceBitwise) {
  const std::string out = expect_query_equals_trace(*gen_, gen_->small_rays, false);
  EXPECT_TRUE(contains(out, "messages 1\n")) << out;
}

TEST_F(ServerE2e, UnaryAnyHitEqualsTraceBitwise) {
  expect_query_equals_trace(*gen_, gen_->small_rays, true);
}

TEST_F(ServerE2e, BatchSeveralTimesTheMaxMessageIsStreamedAndEqualsTrace) {
  const std::string out = expect_query_equals_trace(*gen_, gen_->big_rays, false, {"--no-shared-memory"});
  EXPECT_TRUE(contains(out, "messages 4\nshared_memory no\n")) << out;
  const std::string any = expect_query_equals_trace(*gen_, gen_->big_rays, true, {"--no-shared-memory"});
  EXPECT_TRUE(contains(any, "messages 4\nshared_memory no\n")) << any;
  // By default, a loopback server takes the batch as one shared-memory call.
  const std::string shared = expect_query_equals_trace(*gen_, gen_->big_rays, false);
  EXPECT_TRUE(contains(shared, "messages 1\nshared_memory yes\n")) << shared;
  const std::string shared_any = expect_query_equals_trace(*gen_, gen_->big_rays, true);
  EXPECT_TRUE(contains(shared_any, "messages 1\nshared_memory yes\n")) << shared_any;
}

TEST_F(ServerE2e, UnevenChunksKeepTheirOrder) {
  const std::string out = expect_query_equals_trace(*gen_, gen_->big_rays, false, {"--chunk-rays", "7001"});
  EXPECT_TRUE(contains(out, "messages 15\n")) << out;
  // A small batch split into many chunks, one of them a single ray.
  const std::string small =
      expect_query_equals_trace(*gen_, gen_->small_rays, true, {"--chunk-rays", "2999"});
  EXPECT_TRUE(contains(small, "messages 2\n")) << small;
}

// Over gRPC bytes, a batch of more than 262,144 rays is streamed in
// 65,536-ray chunks by default even when one message would hold it (the wire
// then overlaps tracing), against a server with the default 64 MiB messages.
TEST_F(ServerE2e, LargeBatchesStreamInChunksByDefaultAndEqualTrace) {
  std::string error;
  auto server = ServerProcess::start(gen_->store, {}, error);
  ASSERT_NE(server, nullptr) << error;
  auto store = SceneStore::open(gen_->store);
  ASSERT_TRUE(store.ok());
  const std::string rays = dir_->file("gen-large.npy");
  ASSERT_TRUE(write_rays_npy(rays, testing::make_test_rays((*store)->manifest().bounds, 300'001, 13)).ok());
  const std::string traced = dir_->file("trace-large.npy");
  const std::string queried = dir_->file("query-large.npy");
  const SubprocessResult t = outcore({"trace", gen_->store, "--rays", rays, "-o", traced});
  ASSERT_TRUE(t.succeeded()) << t.describe();
  const SubprocessResult q = outcore({"query", "--server", server->address(), "--rays", rays, "-o", queried,
                                      "--stats", "--no-shared-memory"});
  ASSERT_TRUE(q.succeeded()) << q.describe();
  EXPECT_TRUE(contains(q.stdout_text, "messages 5\n")) << q.stdout_text;  // ceil(300001 / 65536)
  EXPECT_TRUE(read_bytes(queried) == read_bytes(traced)) << "query's hits differ from trace's";
}

TEST_F(ServerE2e, StrictAndNoReorderGiveTheSameAnswer) {
  expect_query_equals_trace(*gen_, gen_->small_rays, false,
                            {"--no-reorder", "--strict", "--deadline-s", "60"});
}

TEST_F(ServerE2e, BunnyUnaryAndStreamedEqualTrace) {
  expect_query_equals_trace(*bunny_, bunny_->small_rays, false);
  expect_query_equals_trace(*bunny_, bunny_->small_rays, true);
  const std::string out = expect_query_equals_trace(*bunny_, bunny_->big_rays, false, {"--no-shared-memory"});
  EXPECT_TRUE(contains(out, "messages 4\n")) << out;
  expect_query_equals_trace(*bunny_, bunny_->big_rays, true, {"--no-shared-memory"});
  const std::string shared = expect_query_equals_trace(*bunny_, bunny_->big_rays, false);
  EXPECT_TRUE(contains(shared, "shared_memory yes\n")) << shared;
}

// The line of `outcore trace --stats`-style text that starts with `prefix`,
// its seconds blanked (empty when there is none).
std::string figures_line(const std::string& text, const std::string& prefix) {
  const auto start = text.find("\n" + prefix);
  if (start == std::string::npos) return "";
  const auto end = text.find('\n', start + 1);
  const std::string line = text.substr(start + 1, end == std::string::npos ? end : end - start - 1);
  return std::regex_replace(line, std::regex("[0-9]+\\.[0-9]+ s\\b"), "_ s");
}

// On a fresh server and a fresh `trace`, one engine thread each (the split of
// candidates into visits and proxy skips can change with the thread count),
// the same rays give the same figures, printed the same way.
TEST_F(ServerE2e, QueryStatsPrintTheFiguresTracePrintsForTheSameRays) {
  std::string error;
  auto server = ServerProcess::start(gen_->store, {"--threads", "1"}, error);
  ASSERT_NE(server, nullptr) << error;
  const SubprocessResult q = outcore({"query", "--server", server->address(), "--rays", gen_->small_rays,
                                      "-o", dir_->file("figures-query.npy"), "--stats"});
  ASSERT_TRUE(q.succeeded()) << q.describe();
  const SubprocessResult t = outcore({"trace", gen_->store, "--rays", gen_->small_rays, "-o",
                                      dir_->file("figures-trace.npy"), "--stats", "--threads", "1"});
  ASSERT_TRUE(t.succeeded()) << t.describe();
  EXPECT_TRUE(contains(q.stdout_text, "messages 1\n")) << q.stdout_text;
  for (const std::string prefix : {"  upper: ", "  bricks: ", "  proxies: "}) {
    const std::string want = figures_line(t.stdout_text, prefix);
    EXPECT_FALSE(want.empty()) << "no '" << prefix << "' line in trace's:\n" << t.stdout_text;
    EXPECT_EQ(figures_line(q.stdout_text, prefix), want) << q.stdout_text;
  }
  EXPECT_TRUE(std::regex_search(q.stdout_text, std::regex("proxies: [0-9]+ of [0-9]+ brick visits skipped")))
      << q.stdout_text;
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

TEST_F(ServerE2e, QueryErrorsNameWhatIsWrong) {
  const std::string out = dir_->file("never.npy");
  SubprocessResult r =
      outcore({"query", "--server", gen_->server->address(), "--rays", dir_->file("missing.npy"), "-o", out});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "missing.npy")) << r.stderr_text;
  // Nothing listens on port 1.
  r = outcore(
      {"query", "--server", "127.0.0.1:1", "--rays", gen_->small_rays, "-o", out, "--deadline-s", "5"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "127.0.0.1:1")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "UNAVAILABLE")) << r.stderr_text;
  r = outcore({"query", "--server", gen_->server->address(), "--rays", gen_->small_rays, "-o", out,
               "--deadline-s", "-1"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "--deadline-s")) << r.stderr_text;
  EXPECT_FALSE(std::ifstream(out).good()) << "a failed query wrote its output";
}

TEST_F(ServerE2e, ServersWithoutProxiesOrAtAnotherProxyResolutionAnswerLikeTrace) {
  const std::vector<std::vector<std::string>> variants = {{"--no-proxies"}, {"--proxy-res", "8"}};
  for (const auto& extra : variants) {
    Scene other;
    other.store = gen_->store;
    std::string error;
    other.server = ServerProcess::start(other.store, extra, error);
    ASSERT_NE(other.server, nullptr) << error;
    expect_query_equals_trace(other, gen_->small_rays, false);
    const std::string log = other.server->log();
    EXPECT_TRUE(
        contains(log, extra[0] == "--no-proxies" ? "brick proxies off" : "brick proxies: resolution 8"))
        << log;
  }
}

TEST_F(ServerE2e, ServeRejectsBadOptionsAndMissingStores) {
  SubprocessResult r = outcore({"serve", dir_->file("no-such-store")});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "no-such-store")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--max-message-mb", "0"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "--max-message-mb")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--stream-group-rays", "-1"});
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "--stream-group-rays")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--log-level", "loud"});
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "loud")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--listen", "nonsense"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "nonsense")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--proxy-res", "0"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "--proxy-res")) << r.stderr_text;
  r = outcore({"serve", gen_->store, "--no-proxies", "--proxy-res", "8"});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "--no-proxies")) << r.stderr_text;
  // The port is taken by the running server.
  r = outcore({"serve", gen_->store, "--listen", gen_->server->address()});
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "cannot listen on")) << r.stderr_text;
}

// A port is 0 to 65535 (0: any free port, for serve only); gRPC's resolver
// would take 99999 modulo 65536 and serve or connect on 34463.
TEST_F(ServerE2e, PortsOutsideTheirRangeOrNotNumbersAreErrorsNamingTheValue) {
  const auto quick = [](std::vector<std::string> args) {
    return testing::run_outcore(std::move(args), std::chrono::milliseconds(10'000));
  };
  for (const std::string listen : {"127.0.0.1:99999", "127.0.0.1:65536", "127.0.0.1:-1", "127.0.0.1:http",
                                   "127.0.0.1:", "127.0.0.1", "[::1]:70000"}) {
    const SubprocessResult r = quick({"serve", gen_->store, "--listen", listen});
    EXPECT_FALSE(r.timed_out) << listen << ": the server started";
    EXPECT_EQ(r.exit_code, 1) << listen << ": " << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, "'" + listen + "'")) << r.stderr_text;
    EXPECT_TRUE(contains(r.stderr_text, "port") || contains(r.stderr_text, "HOST:PORT")) << r.stderr_text;
  }
  const std::string out = dir_->file("never.npy");
  for (const std::string server : {"127.0.0.1:99999", "127.0.0.1:0", "localhost:123456",
                                   "dns:///127.0.0.1:65536", "ipv4:127.0.0.1:1,127.0.0.1:99999"}) {
    const SubprocessResult r =
        quick({"query", "--server", server, "--rays", gen_->small_rays, "-o", out, "--deadline-s", "5"});
    EXPECT_EQ(r.exit_code, 1) << server << ": " << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, "is outside 1 to 65535")) << server << ": " << r.stderr_text;
    EXPECT_FALSE(contains(r.stderr_text, "UNAVAILABLE")) << server << ": " << r.stderr_text;
  }
  EXPECT_FALSE(std::ifstream(out).good()) << "a failed query wrote its output";
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
