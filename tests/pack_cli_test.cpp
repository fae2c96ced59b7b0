// End-to-end tests of `outcore pack` and `outcore info`, run as the real binary:
// bad input is reported with its file and line (or parameter) and leaves
// nothing behind, an interrupted pack cleans up, and packing stays inside its
// memory bound.
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "core/io/npy.h"
#include "core/store/scene_packer.h"
#include "core/store/scene_store.h"
#include "core/util/checksum.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::outcore_binary;
using testing::run_subprocess;
using testing::SubprocessOptions;
using testing::SubprocessResult;
using testing::TempDir;
using testing::write_text_file;

constexpr uint64_t kMiB = 1024 * 1024;
// What a pack process holds besides the packer's own data (bounded by
// --mem-mb): the process image, shared libraries (TBB, Embree, the C++
// runtime), TBB worker stacks and allocator slack.
constexpr uint64_t kPackFixedOverheadMiB = 32;

SubprocessResult outcore(std::vector<std::string> args,
                         std::chrono::milliseconds timeout = std::chrono::milliseconds(300'000)) {
  return testing::run_outcore(std::move(args), timeout);
}

SubprocessOptions timeout_of(std::chrono::milliseconds timeout) {
  SubprocessOptions options;
  options.timeout = timeout;
  return options;
}

// Everything in `dir` (the parent of the would-be store).
std::vector<std::string> entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// A failing pack: non-zero exit, stderr mentions every one of `mentions`, and
// neither the store nor a temporary directory beside it exists.
void expect_pack_fails(const std::vector<std::string>& inputs, const std::vector<std::string>& extra_args,
                       const std::vector<std::string>& mentions) {
  TempDir out;
  const std::string store = out.file("scene");
  std::vector<std::string> args{"pack"};
  args.insert(args.end(), inputs.begin(), inputs.end());
  args.insert(args.end(), {"-o", store, "-q", "--no-sync"});
  args.insert(args.end(), extra_args.begin(), extra_args.end());
  const SubprocessResult r = outcore(args);
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_EQ(r.term_signal, 0) << r.describe();
  for (const std::string& m : mentions)
    EXPECT_TRUE(contains(r.stderr_text, m)) << "no '" << m << "' in:\n" << r.stderr_text;
  EXPECT_TRUE(entries(out.path()).empty()) << "left behind: " << entries(out.path()).front();
}

// ---- the subprocess helper itself -------------------------------------------------

TEST(Subprocess, CapturesStdoutStderrAndExitCode) {
  const auto r = run_subprocess({"/bin/sh", "-c", "echo to-out; echo to-err >&2; exit 3"});
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.term_signal, 0);
  EXPECT_EQ(r.stdout_text, "to-out\n");
  EXPECT_EQ(r.stderr_text, "to-err\n");
}

TEST(Subprocess, TimeoutKillsTheCommand) {
  SubprocessOptions options;
  options.timeout = std::chrono::milliseconds(100);
  const auto r = run_subprocess({"/bin/sleep", "30"}, options);
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_TRUE(r.timed_out);
  EXPECT_EQ(r.term_signal, SIGKILL);
  EXPECT_LT(r.seconds, 10.0);
}

TEST(Subprocess, MissingProgramFailsWithExit127) {
  const auto r = run_subprocess({"/nonexistent/program"});
  EXPECT_EQ(r.exit_code, 127);
  EXPECT_TRUE(contains(r.stderr_text, "/nonexistent/program")) << r.stderr_text;
}

// The command's peak RSS must not include the test process's own memory, which
// a plain fork() would copy into the child before execv.
TEST(Subprocess, PeakRssExcludesTheTestProcessMemory) {
  std::vector<char> ballast(256 * kMiB);
  std::memset(ballast.data(), 1, ballast.size());
  const auto r = run_subprocess({"/bin/sh", "-c", "exit 0"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_GT(r.peak_rss_bytes, 0u);
#ifndef OUTCORE_SANITIZE_BUILD  // the sanitizer runtime's shadow memory dwarfs the bound
  EXPECT_LT(r.peak_rss_bytes, 32 * kMiB);
#endif
  EXPECT_EQ(ballast[ballast.size() / 2], 1);
}

// ---- bad input --------------------------------------------------------------------

TEST(PackCliBadInput, MissingFileFailsNamingTheFile) {
  TempDir in;
  const std::string missing = in.file("nowhere.obj");
  expect_pack_fails({"gen:sphere?level=1", missing}, {}, {missing});
}

TEST(PackCliBadInput, GarbledObjLineFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("garbled.obj");
  write_text_file(obj, "# a comment\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 zero\nf 1 2 3\n");
  expect_pack_fails({obj}, {}, {obj + ":5", "zero"});
}

TEST(PackCliBadInput, DirectoryNamedLikeAnObjFailsNamingIt) {
  TempDir in;
  const std::string obj = in.file("folder.obj");
  fs::create_directory(obj);
  expect_pack_fails({"gen:sphere?level=1", obj}, {}, {obj});
}

TEST(PackCliBadInput, ObjFaceIndexOutOfRangeFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("range.obj");
  write_text_file(obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");
  expect_pack_fails({obj}, {}, {obj + ":5", "4"});
}

TEST(PackCliBadInput, PlyVertexIndexOutOfRangeFailsNamingFileAndIndex) {
  TempDir in;
  const std::string ply = in.file("range.ply");
  write_text_file(
      ply,
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n");
  expect_pack_fails({ply}, {}, {ply + ":14", "7"});
}

TEST(PackCliBadInput, FaceWithFewerThanThreeCornersFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("short.obj");
  write_text_file(obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n");
  expect_pack_fails({obj}, {}, {obj + ":5", "corner"});
}

TEST(PackCliBadInput, NanCoordinateFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("nan.obj");
  write_text_file(obj, "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
  expect_pack_fails({obj}, {}, {obj + ":2"});
}

TEST(PackCliBadInput, CoordinateOverflowingFloatFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("huge.obj");
  write_text_file(obj, "v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n");
  expect_pack_fails({obj}, {}, {obj + ":3"});
}

// Finite in float, but beyond what the float triangle tests handle: Embree
// dropped such triangles silently, and bvh missed hits the reference found.
TEST(PackCliBadInput, CoordinateBeyondTheVertexLimitFailsWithFileAndLine) {
  TempDir in;
  const std::string obj = in.file("far.obj");
  write_text_file(obj, "v 0 0 0\nv 1 0 0\nv 0 1e19 0\nf 1 2 3\n");
  expect_pack_fails({obj}, {}, {obj + ":3", "1e19", "5.5e11"});
  const std::string ply = in.file("far.ply");
  write_text_file(
      ply,
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 -6e11 0\n3 0 1 2\n");
  expect_pack_fails({ply}, {}, {ply + ":12", "5.5e11"});
  // Generators are checked by the packer, naming the input and the triangle.
  expect_pack_fails({"gen:sphere?level=1", "gen:sphere?level=1&radius=1e12"}, {},
                    {"input 1 'gen:sphere?level=1&radius=1e12': triangle 0", "5.5e11"});
}

// At the limit every configuration agrees with the float64 reference: rays
// from anywhere within it, in every direction, at big triangles spanning it.
TEST(PackCliCoordinateLimit, TrianglesAndRaysWithinTheLimitGetTheReferenceAnswers) {
  TempDir dir;
  const std::string obj = dir.file("wide.obj");
  std::mt19937 rng(7);
  const float limit = 0x1p39f;
  std::uniform_real_distribution<float> coordinate(-limit, limit);
  std::string text =
      "v " + std::to_string(limit) + " " + std::to_string(-limit) + " " + std::to_string(limit) + "\n";
  for (int i = 0; i < 40 * 3 - 1; ++i)
    text += "v " + std::to_string(coordinate(rng)) + " " + std::to_string(coordinate(rng)) + " " +
            std::to_string(coordinate(rng)) + "\n";
  for (int i = 0; i < 40; ++i)
    text += "f " + std::to_string(3 * i + 1) + " " + std::to_string(3 * i + 2) + " " +
            std::to_string(3 * i + 3) + "\n";
  write_text_file(obj, text);
  const std::string store = dir.file("scene");
  ASSERT_TRUE(outcore({"pack", obj, "-o", store, "-q", "--no-sync"}).succeeded());
  std::normal_distribution<float> gauss;
  std::vector<Ray> rays(20000);
  for (Ray& ray : rays) {
    ray.origin = Vec3f(coordinate(rng), coordinate(rng), coordinate(rng));
    const Vec3f d(gauss(rng), gauss(rng), gauss(rng));
    ray.direction = d * (1.0f / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z));
  }
  const std::string rays_path = dir.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(rays_path, rays).ok());
  const auto trace = [&](const std::vector<std::string>& mode) {
    std::vector<std::string> args{"trace", store, "--rays", rays_path, "-o", dir.file("hits.npy")};
    args.insert(args.end(), mode.begin(), mode.end());
    const auto r = outcore(args);
    EXPECT_TRUE(r.succeeded()) << r.describe();
    auto hits = read_hits_npy(dir.file("hits.npy"));
    EXPECT_TRUE(hits.ok()) << hits.status().to_string();
    return hits.ok() ? *hits : std::vector<Hit>{};
  };
  const std::vector<Hit> reference = trace({"--reference"});
  ASSERT_EQ(reference.size(), rays.size());
  const auto hit_count =
      std::count_if(reference.begin(), reference.end(), [](const Hit& h) { return h.is_hit(); });
  EXPECT_GT(hit_count, 5000);
  for (const auto& mode : std::vector<std::vector<std::string>>{
           {}, {"--brick-accel", "bvh"}, {"--brick-accel", "bvh", "--triangle-test", "mt"}}) {
    SCOPED_TRACE(mode.empty() ? "embree" : mode.back());
    const std::vector<Hit> hits = trace(mode);
    ASSERT_EQ(hits.size(), rays.size());
    uint64_t differ = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
      // t is as accurate as the coordinates allow: the float tests' rounding
      // (hit_rounding.h, 2^-15 of the magnitudes for Moeller-Trumbore) along
      // a unit direction.
      const double slack = 0x1p-15 * (2.0 * limit);
      const bool same = hits[i].primitive_id == reference[i].primitive_id &&
                        (!reference[i].is_hit() ||
                         std::fabs(double{hits[i].t} - reference[i].t) <= 1e-4 * reference[i].t + slack);
      if (!same && differ++ < 5) {
        ADD_FAILURE() << "ray " << i << ": t " << hits[i].t << " id " << hits[i].primitive_id
                      << ", reference t " << reference[i].t << " id " << reference[i].primitive_id;
      }
    }
    EXPECT_EQ(differ, 0u) << "of " << hit_count << " reference hits";
  }
}

TEST(PackCliBadInput, SceneWithoutTrianglesFailsAsEmpty) {
  TempDir in;
  const std::string obj = in.file("points.obj");
  write_text_file(obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  expect_pack_fails({obj}, {}, {"empty"});
}

TEST(PackCliBadInput, UnknownGeneratorFailsNamingIt) {
  expect_pack_fails({"gen:sphere?level=1", "gen:dodecahedron"}, {}, {"dodecahedron"});
}

TEST(PackCliBadInput, UnknownGeneratorParameterFailsNamingIt) {
  expect_pack_fails({"gen:sphere?levle=2"}, {}, {"levle"});
}

TEST(PackCliBadInput, OutOfRangeGeneratorParameterFailsNamingIt) {
  expect_pack_fails({"gen:terrain?n=0"}, {}, {"'n'"});
}

TEST(PackCliBadInput, UnsupportedExtensionFails) {
  TempDir in;
  const std::string stl = in.file("model.stl");
  write_text_file(stl, "solid x\nendsolid x\n");
  expect_pack_fails({stl}, {}, {stl, "unsupported"});
}

TEST(PackCliBadInput, ZeroBrickTrianglesFailsNamingTheOption) {
  expect_pack_fails({"gen:sphere?level=1"}, {"--brick-tris", "0"}, {"--brick-tris"});
}

TEST(PackCliBadInput, TooSmallMemoryBudgetFailsNamingTheOption) {
  expect_pack_fails({"gen:sphere?level=1"}, {"--mem-mb", "16"}, {"--mem-mb"});
}

TEST(PackCliBadInput, ExistingOutputWithoutForceFailsAndSaysSo) {
  TempDir out;
  const std::string store = out.file("scene");
  ASSERT_TRUE(outcore({"pack", "gen:sphere?level=1", "-o", store, "-q", "--no-sync"}).succeeded());
  const auto r = outcore({"pack", "gen:torus", "-o", store, "-q", "--no-sync"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.stderr_text, "--force")) << r.stderr_text;
  auto opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ((*opened)->manifest().inputs[0].spec, "gen:sphere?level=1");
  const auto forced = outcore({"pack", "gen:torus", "-o", store, "-q", "--no-sync", "--force"});
  EXPECT_TRUE(forced.succeeded()) << forced.describe();
  opened = SceneStore::open(store);
  ASSERT_TRUE(opened.ok());
  EXPECT_EQ((*opened)->manifest().inputs[0].spec, "gen:torus");
  EXPECT_EQ(entries(out.path()), std::vector<std::string>{"scene"});
}

// The probe's finding: --force deleted a directory of the user's files.
TEST(PackCliBadInput, ForceOntoADirectoryOfUserFilesFailsNamingItAndKeepsThem) {
  TempDir out;
  const std::string target = out.file("documents");
  fs::create_directories(target + "/sub");
  write_text_file(target + "/sub/letter.txt", "precious");
  const auto r = outcore({"pack", "gen:sphere?level=1", "-o", target, "-q", "--no-sync", "--force"});
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, target)) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "not an Outcore store")) << r.stderr_text;
  EXPECT_EQ(testing::read_file_bytes(target + "/sub/letter.txt"), "precious");
  EXPECT_EQ(entries(out.path()), std::vector<std::string>{"documents"});
}

// Opening a FIFO for reading waits for a writer: pack used to hang there. A
// device is no scene file either (/dev/null read as an empty OBJ).
TEST(PackCliBadInput, FifoOrDeviceInputFailsPromptlyNamingIt) {
  TempDir in;
  const std::string fifo = in.file("pipe.obj");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  const std::string device = in.file("null.obj");
  fs::create_symlink("/dev/null", device);
  for (const auto& [input, kind] : {std::pair{fifo, "FIFO"}, std::pair{device, "character device"}}) {
    SCOPED_TRACE(input);
    TempDir out;
    const auto r = outcore({"pack", "gen:sphere?level=1", input, "-o", out.file("scene"), "-q", "--no-sync"},
                           std::chrono::milliseconds(10'000));
    EXPECT_FALSE(r.timed_out) << "pack hung on " << input;
    EXPECT_NE(r.exit_code, 0) << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, input)) << r.stderr_text;
    EXPECT_TRUE(contains(r.stderr_text, kind)) << r.stderr_text;
    EXPECT_TRUE(entries(out.path()).empty()) << "left behind: " << entries(out.path()).front();
  }
}

// Not an OBJ at all (an archive renamed): every line is an unknown statement,
// so it parses to no triangles.
std::string write_garbage_obj(const TempDir& in) {
  const std::string obj = in.file("garbage.obj");
  write_text_file(obj, "PK\x03\x04 archive bytes\nmore bytes\n");
  return obj;
}

TEST(PackCliEmptyInput, AnInputWithoutTrianglesBesideValidOnesIsAWarningNamingIt) {
  TempDir in, out;
  const std::string obj = write_garbage_obj(in);
  const auto r = outcore({"pack", "gen:sphere?level=1", obj, "-o", out.file("scene"), "-q", "--no-sync"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "input 1 '" + obj + "' has no triangles")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "warn")) << r.stderr_text;
}

TEST(PackCliEmptyInput, AnInputWithoutTrianglesIsAnErrorUnderStrict) {
  TempDir in;
  const std::string obj = write_garbage_obj(in);
  expect_pack_fails({"gen:sphere?level=1", obj}, {"--strict"}, {"input 1 '" + obj + "' has no triangles"});
}

// ---- permissions --------------------------------------------------------------------

// A store is read by servers that may run as another user: its directory and
// files get the usual modes under the umask (mkdtemp made the directory 0700).
TEST(PackCliPermissions, StoreModesFollowTheUmask) {
  for (const auto& [umask, dir_mode, file_mode] :
       {std::tuple{"022", 0755, 0644}, std::tuple{"077", 0700, 0600}}) {
    SCOPED_TRACE(std::string("umask ") + umask);
    TempDir out;
    const std::string store = out.file("scene");
    const auto r =
        run_subprocess({"/bin/sh", "-c", std::string("umask ") + umask + " && exec \"$0\" \"$@\"",
                        outcore_binary(), "pack", "gen:sphere?level=1", "-o", store, "-q", "--no-sync"});
    ASSERT_TRUE(r.succeeded()) << r.describe();
    const auto mode = [](const std::string& path) {
      return static_cast<int>(fs::status(path).permissions() & fs::perms::mask);
    };
    EXPECT_EQ(mode(store), dir_mode);
    EXPECT_EQ(mode(store + "/manifest.bin"), file_mode);
    EXPECT_EQ(mode(store + "/bricks.dat"), file_mode);
  }
}

// ---- leftovers of killed packs ------------------------------------------------------

TEST(PackCliStalePartials, TheNextPackRemovesThoseOfDeadPacksOfItsOutputAndSaysSo) {
  TempDir out;
  const std::string store = out.file("scene");
  // A pack killed outright (SIGKILL: no handler runs) once its temporary
  // directory exists.
  const auto killed = run_subprocess(
      {"/bin/sh", "-c",
       "\"$0\" \"$@\" & p=$!; until ls -d \"$4\".partial-* >/dev/null 2>&1; do sleep 0.01; done; "
       "kill -KILL $p; wait $p; ls -d \"$4\".partial-*",
       outcore_binary(), "pack", "gen:city?of=(gen:sphere?level=5)&copies=150", "-o", store, "--mem-mb", "64",
       "-q", "--no-sync"},
      timeout_of(std::chrono::milliseconds(60'000)));
  ASSERT_FALSE(killed.timed_out) << killed.describe();
  const std::string stale = killed.stdout_text.substr(0, killed.stdout_text.find('\n'));
  ASSERT_TRUE(contains(stale, store + ".partial-")) << killed.describe();
  ASSERT_TRUE(fs::is_directory(stale));
  // What must stay: a running process's (this test's pid), another output's,
  // and one named as by older versions (no pid: whose it is cannot be told).
  const std::string live = store + ".partial-" + std::to_string(::getpid()) + "-Live12";
  const std::string pid_part = stale.substr(store.size() + std::strlen(".partial-"));
  const std::string other = out.file("other.partial-" + pid_part);
  const std::string old_style = store + ".partial-Xy12Zq";
  for (const std::string& dir : {live, other, old_style}) fs::create_directory(dir);

  const auto r = outcore({"pack", "gen:sphere?level=1", "-o", store, "-q", "--no-sync"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_FALSE(fs::exists(stale));
  EXPECT_TRUE(contains(r.stderr_text, "removed " + stale)) << r.stderr_text;
  for (const std::string& dir : {live, other, old_style}) EXPECT_TRUE(fs::is_directory(dir)) << dir;
  EXPECT_TRUE(SceneStore::open(store).ok());
}

// ---- info ---------------------------------------------------------------------------

class InfoCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto r = outcore(
        {"pack", "gen:sphere?level=2", "gen:torus", "-o", store_, "-q", "--no-sync", "--brick-tris", "100"});
    ASSERT_TRUE(r.succeeded()) << r.describe();
    auto opened = SceneStore::open(store_);
    ASSERT_TRUE(opened.ok());
    bricks_ = (*opened)->brick_count();
  }
  TempDir dir_;
  std::string store_ = dir_.file("scene");
  uint32_t bricks_ = 0;
};

TEST_F(InfoCliTest, PrintsTheTriangleCount) {
  const auto r = outcore({"info", store_});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stdout_text, "4416")) << r.stdout_text;  // 320 + 4096
  EXPECT_TRUE(contains(r.stdout_text, std::to_string(bricks_))) << r.stdout_text;
}

TEST_F(InfoCliTest, JsonHasTheSceneTriangleAndBrickCounts) {
  const auto r = outcore({"info", store_, "--json"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const std::string& json = r.stdout_text;
  ASSERT_FALSE(json.empty());
  EXPECT_EQ(json.front(), '{');
  // The scene's keys follow the inputs array; the inputs have their own counts.
  const size_t after_inputs = json.find(']');
  ASSERT_NE(after_inputs, std::string::npos) << json;
  const std::string scene = json.substr(after_inputs);
  EXPECT_TRUE(contains(scene, "\"triangles\":4416")) << json;
  EXPECT_TRUE(contains(scene, "\"bricks\":" + std::to_string(bricks_) + ",")) << json;
  EXPECT_TRUE(contains(json, "\"triangles\":320")) << json;
  EXPECT_TRUE(contains(json, "\"triangles\":4096")) << json;
}

TEST(InfoCli, MissingStoreFailsNamingThePath) {
  TempDir dir;
  const auto r = outcore({"info", dir.file("absent")});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.stderr_text, dir.file("absent"))) << r.stderr_text;
}

// ---- interruption -------------------------------------------------------------------

// About 20M triangles: far more than the pack can finish in the time allowed.
const std::string kHugeCity = "gen:city?of=(gen:sphere?level=5)&copies=977";

void expect_interrupted_cleanly(const SubprocessResult& r, const TempDir& out) {
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_TRUE(r.interrupted);
  EXPECT_FALSE(r.timed_out) << "SIGINT did not stop the pack";
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "interrupted")) << r.stderr_text;
  EXPECT_TRUE(entries(out.path()).empty()) << "left behind: " << entries(out.path()).front();
}

TEST(PackCliInterrupt, SigintAfter300MsExitsNonZeroAndLeavesNothing) {
  TempDir out;
  SubprocessOptions options;
  options.interrupt_after = std::chrono::milliseconds(300);
  options.timeout = std::chrono::milliseconds(60'000);
  const auto r = run_subprocess(
      {outcore_binary(), "pack", kHugeCity, "-o", out.file("scene"), "--mem-mb", "64", "-q", "--no-sync"},
      options);
  expect_interrupted_cleanly(r, out);
}

// SIGINT once the temporary store exists beside the output, so the cleanup of
// half-written data is what is being tested.
TEST(PackCliInterrupt, SigintWhileWritingRemovesThePartialDirectory) {
  TempDir out;
  SubprocessOptions options;
  options.interrupt_when = [&] {
    for (const auto& entry : fs::directory_iterator(out.path())) {
      if (contains(entry.path().filename().string(), ".partial-")) return true;
    }
    return false;
  };
  options.timeout = std::chrono::milliseconds(60'000);
  const auto r = run_subprocess({outcore_binary(), "pack", "gen:city?of=(gen:sphere?level=5)&copies=150",
                                 "-o", out.file("scene"), "--mem-mb", "64", "-q", "--no-sync"},
                                options);
  ASSERT_TRUE(r.interrupted) << "the pack ended before its temporary directory was seen: " << r.describe();
  expect_interrupted_cleanly(r, out);
}

// SIGTERM while gen:city reads a large base (84 M triangles: its welding used
// to run to the end, 47 s here, before the signal was looked at).
TEST(PackCliInterrupt, SigtermWhileACityReadsItsBaseExitsWithinFiveSecondsAndLeavesNothing) {
  TempDir out;
  const auto r = run_subprocess(
      {"/bin/sh", "-c",
       "\"$0\" \"$@\" & p=$!; sleep 1; kill -TERM $p; s=$(date +%s%N); wait $p; rc=$?; e=$(date +%s%N); "
       "echo \"exit $rc after $(( (e - s) / 1000000 )) ms\"",
       outcore_binary(), "pack", "gen:city?of=(gen:sphere?level=11)&copies=2", "-o", out.file("scene"),
       "--mem-mb", "8192", "-q", "--no-sync"},
      timeout_of(std::chrono::milliseconds(120'000)));
  ASSERT_TRUE(r.succeeded()) << r.describe();
  int exit_code = -1;
  long ms = -1;
  ASSERT_EQ(std::sscanf(r.stdout_text.c_str(), "exit %d after %ld ms", &exit_code, &ms), 2) << r.stdout_text;
  EXPECT_NE(exit_code, 0) << r.stderr_text;
  EXPECT_LT(ms, 5000) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "interrupted")) << r.stderr_text;
  EXPECT_TRUE(entries(out.path()).empty()) << "left behind: " << entries(out.path()).front();
}

// ---- memory bound -------------------------------------------------------------------

// 64-bit XXH3 of every triangle, indexed by primitive id (one input), plus
// checks that every id occurs exactly once.
std::vector<uint64_t> triangle_fingerprints(const std::string& store_dir, uint64_t expected) {
  auto opened = SceneStore::open(store_dir);
  EXPECT_TRUE(opened.ok()) << opened.status().to_string();
  if (!opened.ok()) return {};
  const SceneStore& store = **opened;
  EXPECT_EQ(store.manifest().triangle_count, expected);
  std::vector<uint64_t> hashes(expected, 0);
  std::vector<uint8_t> seen(expected, 0);
  uint64_t bad_ids = 0;
  BrickData brick;
  for (uint32_t b = 0; b < store.brick_count(); ++b) {
    const Status s = store.load_brick(b, brick);
    EXPECT_TRUE(s.ok()) << s.to_string();
    if (!s.ok()) return {};
    for (size_t i = 0; i < brick.ids.size(); ++i) {
      const TriangleId id = brick.ids[i];
      if (id.geometry_id != 0 || id.primitive_id >= expected || seen[id.primitive_id]++) {
        ++bad_ids;
        continue;
      }
      hashes[id.primitive_id] = checksum64(&brick.triangles[i], sizeof(Triangle));
    }
  }
  EXPECT_EQ(bad_ids, 0u) << "unknown or repeated ids";
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<long>(expected)) << "ids missing";
  return hashes;
}

TEST(PackCliMemory, PeakRssStaysWithinMemMbPlusFixedOverheadAndResultMatchesAnInMemoryPack) {
  // 293 copies of a 20480-triangle sphere: 6.0M triangles, 252 MiB raw, about
  // four times the 64 MiB budget.
  const std::string city = "gen:city?of=(gen:sphere?level=5)&copies=293";
  const uint64_t triangles = 293ull * 20480;
  const uint64_t mem_mb = 64;
  TempDir out;
  const auto small =
      outcore({"pack", city, "-o", out.file("small"), "--mem-mb", std::to_string(mem_mb), "-q", "--no-sync"});
  ASSERT_TRUE(small.succeeded()) << small.describe();
  EXPECT_GE(triangles * sizeof(PackedTriangle), 3 * mem_mb * kMiB);
  EXPECT_GT(small.peak_rss_bytes, 0u);
#ifndef OUTCORE_SANITIZE_BUILD  // sanitizer shadow memory and quarantine dwarf the bound
  EXPECT_LE(small.peak_rss_bytes, (mem_mb + kPackFixedOverheadMiB) * kMiB)
      << "peak RSS " << small.peak_rss_bytes / kMiB << " MiB";
#endif
  std::printf("pack of %llu triangles at --mem-mb %llu: peak RSS %.1f MiB\n",
              static_cast<unsigned long long>(triangles), static_cast<unsigned long long>(mem_mb),
              static_cast<double>(small.peak_rss_bytes) / kMiB);
  EXPECT_FALSE(contains(small.stdout_text, "out-of-core levels 0")) << small.stdout_text;

  const auto large = outcore({"pack", city, "-o", out.file("large"), "--mem-mb", "1024", "-q", "--no-sync"});
  ASSERT_TRUE(large.succeeded()) << large.describe();
  EXPECT_TRUE(contains(large.stdout_text, "out-of-core levels 0")) << large.stdout_text;

  const std::vector<uint64_t> a = triangle_fingerprints(out.file("small"), triangles);
  const std::vector<uint64_t> b = triangle_fingerprints(out.file("large"), triangles);
  ASSERT_EQ(a.size(), triangles);
  ASSERT_EQ(b.size(), triangles);
  size_t differing = 0;
  for (size_t i = 0; i < a.size(); ++i) differing += a[i] != b[i];
  EXPECT_EQ(differing, 0u) << "triangles stored differently by the out-of-core and in-memory packs";
}

// A side x side grid of vertices written in a scrambled order (file position
// f holds grid vertex f * kStride mod n), then one triangle (i, i+1, i+side)
// for every third grid cell, so faces index vertices all over the file as in
// a large scan. Returns the triangle count.
uint64_t write_scrambled_grid_obj(const std::string& path, uint32_t side) {
  const uint64_t n = uint64_t{side} * side;
  constexpr uint64_t kStride = 1'000'003;  // prime, so coprime with n: a permutation
  EXPECT_NE(n % kStride, 0u);
  std::vector<uint32_t> file_index(n);  // 1-based OBJ index of each grid vertex
  std::FILE* file = std::fopen(path.c_str(), "w");
  EXPECT_NE(file, nullptr) << path;
  if (file == nullptr) return 0;
  std::vector<char> text;
  const auto flush = [&] {
    EXPECT_EQ(std::fwrite(text.data(), 1, text.size(), file), text.size());
    text.clear();
  };
  char line[96];
  for (uint64_t f = 0; f < n; ++f) {
    const uint64_t g = f * kStride % n;
    file_index[g] = static_cast<uint32_t>(f + 1);
    const int length = std::snprintf(line, sizeof line, "v %u %u.5 %u\n", static_cast<unsigned>(g % side),
                                     static_cast<unsigned>(g / side), static_cast<unsigned>(g % 7));
    text.insert(text.end(), line, line + length);
    if (text.size() > (1u << 20)) flush();
  }
  uint64_t triangles = 0;
  for (uint64_t g = 0; g + side + 1 < n; g += 3) {
    if (g % side == side - 1) continue;  // the last column has no cell
    const int length = std::snprintf(line, sizeof line, "f %u %u %u\n", file_index[g], file_index[g + 1],
                                     file_index[g + side]);
    text.insert(text.end(), line, line + length);
    if (text.size() > (1u << 20)) flush();
    ++triangles;
  }
  flush();
  EXPECT_EQ(std::fclose(file), 0);
  return triangles;
}

// Vertex positions alone (4 M vertices, 48 MB) exceed the whole 32 MiB budget;
// the reader resolves the faces out of core, so the bound holds.
TEST(PackCliMemory, IndexedObjWithMoreVertexBytesThanMemMbStaysWithinTheBoundAndMatchesAnInMemoryPack) {
  TempDir out;
  const std::string obj = out.file("scrambled-grid.obj");
  const uint64_t triangles = write_scrambled_grid_obj(obj, 2000);
  const uint64_t mem_mb = kMinPackMemoryMb;
  ASSERT_GT(2000ull * 2000 * sizeof(Vec3f), mem_mb * kMiB);
  const auto small =
      outcore({"pack", obj, "-o", out.file("small"), "--mem-mb", std::to_string(mem_mb), "-q", "--no-sync"});
  ASSERT_TRUE(small.succeeded()) << small.describe();
  EXPECT_GT(small.peak_rss_bytes, 0u);
#ifndef OUTCORE_SANITIZE_BUILD  // sanitizer shadow memory and quarantine dwarf the bound
  EXPECT_LE(small.peak_rss_bytes, (mem_mb + kPackFixedOverheadMiB) * kMiB)
      << "peak RSS " << small.peak_rss_bytes / kMiB << " MiB";
  EXPECT_LT(small.peak_rss_bytes, 2000ull * 2000 * sizeof(Vec3f)) << "less than the positions alone";
#endif
  // The default budget holds the vertices in memory.
  const auto large = outcore({"pack", obj, "-o", out.file("large"), "-q", "--no-sync"});
  ASSERT_TRUE(large.succeeded()) << large.describe();
  std::printf(
      "pack of a %llu-triangle OBJ with 4 M vertices: peak RSS %.1f MiB at --mem-mb %llu, %.1f MiB at "
      "the default\n",
      static_cast<unsigned long long>(triangles), static_cast<double>(small.peak_rss_bytes) / kMiB,
      static_cast<unsigned long long>(mem_mb), static_cast<double>(large.peak_rss_bytes) / kMiB);
  EXPECT_EQ(entries(out.path()), (std::vector<std::string>{"large", "scrambled-grid.obj", "small"}));

  const std::vector<uint64_t> a = triangle_fingerprints(out.file("small"), triangles);
  const std::vector<uint64_t> b = triangle_fingerprints(out.file("large"), triangles);
  ASSERT_EQ(a.size(), triangles);
  ASSERT_EQ(b.size(), triangles);
  EXPECT_TRUE(a == b) << "triangles stored differently by the out-of-core and in-memory reads";
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
