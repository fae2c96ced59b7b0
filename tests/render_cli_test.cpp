// End-to-end tests of `outcore render`, run as the real binary on a small
// generated scene (a terrain and two icospheres: generators that use only
// basic IEEE operations, so the scene is bit-identical on every machine):
// - each mode's picture matches its reference in tests/data/render/. The
//   tolerance: at most 0.5 % of the pixels may differ by more than 2 in a
//   channel, so that another CPU's rounding in the engine (a hit's t, a
//   normal) cannot fail the test while a wrong camera, colour rule or row
//   order does. Regenerate the references after a deliberate change with
//   OUTCORE_UPDATE_RENDER_REFERENCES=1 (and look at them);
// - through a real `outcore serve`, the picture is byte-identical to the
//   in-process one, over shared memory and over gRPC bytes;
// - bad options are errors naming the option and value (exit code 1), and
//   nothing is written then; an existing picture is replaced whole.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "tests/support/png_reader.h"
#include "tests/support/server_process.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::DecodedPng;
using testing::read_file_bytes;
using testing::read_png;
using testing::ServerProcess;
using testing::SubprocessResult;
using testing::TempDir;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(120'000));
}

std::string reference_path(const std::string& mode) {
  return std::string(OUTCORE_SOURCE_DIR) + "/tests/data/render/scene-" + mode + ".png";
}

// The camera of every picture here: above and beside the scene, looking at
// the big sphere, with the world's up (y) as --up: the picture is upright;
// the reference pictures were made with the world's down under Open3D's
// own convention, which asks the camera for the same rays.
std::vector<std::string> camera_args() {
  return {"--eye", "7,5.5,9", "--center", "0,1.2,0", "--up", "0,1,0", "--fov", "55", "--size", "96x72"};
}

class RenderCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    store_ = dir_->file("scene");
    const SubprocessResult packed =
        outcore({"pack", "gen:terrain?n=24&size=14&height=0.6", "gen:sphere?level=3&radius=1.5&cy=1.6",
                 "gen:sphere?level=2&radius=0.8&cx=3&cy=1&cz=-2.5", "-o", store_, "--brick-tris", "400", "-q",
                 "--no-sync"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  // Renders in process into `path`; asserts success.
  static void render(const std::string& mode, const std::string& path, std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"render", store_};
    for (const std::string& a : camera_args()) args.push_back(a);
    for (const std::string& a : {std::string("--mode"), mode, std::string("-o"), path}) args.push_back(a);
    for (const std::string& a : extra) args.push_back(a);
    const SubprocessResult r = outcore(args);
    ASSERT_TRUE(r.succeeded()) << r.describe();
  }

  static TempDir* dir_;
  static std::string store_;
};

TempDir* RenderCli::dir_ = nullptr;
std::string RenderCli::store_;

TEST_F(RenderCli, PicturesMatchTheirReferences) {
  const bool update = std::getenv("OUTCORE_UPDATE_RENDER_REFERENCES") != nullptr;
  for (const std::string mode : {"depth", "normals", "ids"}) {
    SCOPED_TRACE(mode);
    const std::string out = dir_->file(mode + ".png");
    render(mode, out);
    if (update) fs::copy_file(out, reference_path(mode), fs::copy_options::overwrite_existing);
    const DecodedPng got = read_png(out);
    const DecodedPng want = read_png(reference_path(mode));
    ASSERT_EQ(got.error, "");
    ASSERT_EQ(want.error, "");
    ASSERT_EQ(got.width, 96u);
    ASSERT_EQ(got.height, 72u);
    ASSERT_EQ(want.width, got.width);
    ASSERT_EQ(want.height, got.height);
    std::size_t differing = 0;
    std::size_t black = 0;
    for (std::size_t p = 0; p < got.rgb.size() / 3; ++p) {
      bool differs = false;
      for (int c = 0; c < 3; ++c) differs |= std::abs(got.rgb[3 * p + c] - want.rgb[3 * p + c]) > 2;
      differing += differs;
      black += got.rgb[3 * p] == 0 && got.rgb[3 * p + 1] == 0 && got.rgb[3 * p + 2] == 0;
    }
    const std::size_t pixels = std::size_t{got.width} * got.height;
    EXPECT_LE(differing * 200, pixels) << differing << " of " << pixels << " pixels differ by more than 2";
    // The scene fills most of the picture, with sky above the horizon.
    EXPECT_GT(black, pixels / 50);
    EXPECT_LT(black, pixels / 2);
  }
}

TEST_F(RenderCli, PrintsATimingLineAndQuietSilencesIt) {
  std::vector<std::string> args = {"render", store_, "-o", dir_->file("timed.png")};
  for (const std::string& a : camera_args()) args.push_back(a);
  SubprocessResult r = outcore(args);
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stderr_text, "outcore render: 6912 rays (")) << r.stderr_text;
  EXPECT_TRUE(contains(r.stderr_text, "M rays/s in process; 96x72 depth image written to")) << r.stderr_text;
  args.push_back("-q");
  r = outcore(args);
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_EQ(r.stderr_text, "");
  EXPECT_EQ(r.stdout_text, "");
}

TEST_F(RenderCli, EngineOptionsGiveTheSamePicture) {
  const std::string plain = dir_->file("plain.png");
  render("normals", plain);
  const std::string tuned = dir_->file("tuned.png");
  render("normals", tuned, {"--cache-mb", "1", "--brick-accel", "embree", "--threads", "1", "--no-proxies"});
  const DecodedPng a = read_png(plain);
  const DecodedPng b = read_png(tuned);
  ASSERT_EQ(a.error, "");
  ASSERT_EQ(b.error, "");
  std::size_t differing = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) differing += a.rgb[i] != b.rgb[i];
  // Embree's triangle test may decide a pixel on an edge differently.
  EXPECT_LE(differing, a.rgb.size() / 200);
}

// The arguments of a render of the test scene with some camera options
// replaced (an empty value drops the option).
std::vector<std::string> render_args(const std::vector<std::string>& head, const std::string& out,
                                     const std::map<std::string, std::string>& changes) {
  std::vector<std::string> args = head;
  const std::vector<std::string> camera = camera_args();
  for (std::size_t i = 0; i < camera.size(); i += 2) {
    const auto change = changes.find(camera[i]);
    const std::string value = change == changes.end() ? camera[i + 1] : change->second;
    if (value.empty()) continue;
    args.push_back(camera[i]);
    args.push_back(value);
  }
  for (const auto& [option, value] : changes) {
    if (option.rfind("--", 0) == 0 && std::find(camera.begin(), camera.end(), option) == camera.end()) {
      args.push_back(option);
      if (!value.empty()) args.push_back(value);
    }
  }
  args.push_back("-o");
  args.push_back(out);
  return args;
}

TEST_F(RenderCli, ServerPicturesAreByteIdenticalToInProcessOnes) {
  std::string error;
  auto server = ServerProcess::start(store_, {}, error);
  ASSERT_NE(server, nullptr) << error;
  // 19,200 rays: at least kSharedMinRays, so the default remote path goes
  // through shared memory and --no-shared-memory through gRPC bytes.
  const std::map<std::string, std::string> size = {{"--size", "160x120"}};
  for (const std::string mode : {"depth", "normals", "ids"}) {
    SCOPED_TRACE(mode);
    const std::string local = dir_->file("local-" + mode + ".png");
    const SubprocessResult in_process = outcore(render_args({"render", store_, "--mode", mode}, local, size));
    ASSERT_TRUE(in_process.succeeded()) << in_process.describe();
    for (const bool shared : {true, false}) {
      const std::string remote = dir_->file("remote-" + mode + ".png");
      std::vector<std::string> head = {"render", "--server", server->address(), "--mode", mode};
      if (!shared) head.push_back("--no-shared-memory");
      const SubprocessResult r = outcore(render_args(head, remote, size));
      ASSERT_TRUE(r.succeeded()) << r.describe();
      EXPECT_TRUE(contains(r.stderr_text, "19200 rays (")) << r.stderr_text;
      EXPECT_TRUE(contains(r.stderr_text, "M rays/s by " + server->address())) << r.stderr_text;
      const std::string remote_bytes = read_file_bytes(remote);
      ASSERT_FALSE(remote_bytes.empty());
      EXPECT_TRUE(remote_bytes == read_file_bytes(local)) << "shared memory " << shared;
    }
  }
  EXPECT_EQ(server->stop(SIGTERM), 0) << server->log();
}

TEST_F(RenderCli, BadOptionsAreErrorsNamingThem) {
  const std::string out = dir_->file("bad.png");
  const std::vector<std::string> local = {"render", store_};
  struct Case {
    std::vector<std::string> head;
    std::map<std::string, std::string> changes;
    std::string message;
  };
  const std::vector<Case> cases = {
      {local, {{"--size", "640"}}, "--size '640': expected WIDTHxHEIGHT in pixels (e.g. 640x480)"},
      {local, {{"--size", "0x10"}}, "--size '0x10': width and height must be 1 to 16384 pixels"},
      {local, {{"--size", "20000x10"}}, "--size '20000x10': width and height must be 1 to 16384 pixels"},
      {local, {{"--eye", "nan,0,0"}}, "--eye nan,0,0: every component must be finite"},
      {local, {{"--center", "inf,1,1"}}, "--center inf,1,1: every component must be finite"},
      {local, {{"--eye", "1,2"}}, "--eye '1,2': expected three numbers X,Y,Z"},
      {local,
       {{"--eye", "1,2,3"}, {"--center", "1,2,3"}},
       "--eye 1,2,3 and --center 1,2,3 are the same point"},
      {local, {{"--up", "7,4.3,9"}}, "--up 7,4.3,9 is parallel to the view direction"},
      {local, {{"--up", "0,0,0"}}, "--up 0,0,0: must be non-zero"},
      {local,
       {{"--fov", "0"}},
       "--fov 0: the horizontal field of view must be more than 0 and less than 180"},
      {local, {{"--fov", "180"}}, "--fov 180: the horizontal field of view must be"},
      {local, {{"--fov", "-10"}}, "--fov -10: the horizontal field of view must be"},
      {local, {{"--mode", "colour"}}, "--mode 'colour': must be depth, normals or ids"},
      {{"render"}, {}, "give a scene STORE, or --server HOST:PORT"},
      {{"render", store_, "--server", "127.0.0.1:9"},
       {},
       "give a scene STORE or --server HOST:PORT, not both"},
      {{"render", "--server", "127.0.0.1:9"},
       {{"--cache-mb", "64"}},
       "--cache-mb configures the in-process engine; the server at --server 127.0.0.1:9 has its own"},
      {local, {{"--deadline-s", "5"}}, "--deadline-s applies with --server only"},
      {local, {{"--no-shared-memory", ""}}, "--no-shared-memory applies with --server only"},
      {{"render", "--server", "127.0.0.1:9"}, {{"--deadline-s", "-1"}}, "--deadline-s must be a number >= 0"},
      {{"render", dir_->file("no-such-store")}, {}, "no-such-store"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.message);
    const SubprocessResult r = outcore(render_args(c.head, out, c.changes));
    EXPECT_EQ(r.exit_code, 1) << r.describe();
    EXPECT_TRUE(contains(r.stderr_text, "outcore render: error: ")) << r.stderr_text;
    EXPECT_TRUE(contains(r.stderr_text, c.message)) << r.stderr_text;
    EXPECT_FALSE(fs::exists(out));
  }
  // The output's directory is checked before any tracing.
  const std::string nowhere = dir_->file("missing/dir/a.png");
  const SubprocessResult r = outcore(render_args(local, nowhere, {}));
  EXPECT_EQ(r.exit_code, 1) << r.describe();
  EXPECT_TRUE(
      contains(r.stderr_text, "-o " + nowhere + ": " + dir_->file("missing/dir") + " is not a directory"))
      << r.stderr_text;
}

TEST_F(RenderCli, ReplacesAnExistingPictureWholeAndTakesNegativeNumbers) {
  TempDir out_dir;
  const std::string out = out_dir.file("picture.png");
  testing::write_text_file(out, "an older picture");
  // "-7,..." is a value, not an option.
  const SubprocessResult r = outcore(render_args({"render", store_}, out, {{"--eye", "-7,5.5,-9"}}));
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const DecodedPng png = read_png(out);
  EXPECT_EQ(png.error, "");
  EXPECT_EQ(png.width, 96u);
  // Nothing beside it: the temporary was renamed over the old file.
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(out_dir.path())) files += entry.is_regular_file();
  EXPECT_EQ(files, 1u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
