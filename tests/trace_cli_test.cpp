// End-to-end tests of `outcore trace`, run as the real binary: the hits file
// is bitwise the in-process QueryEngine answer whatever the reordering, cache
// budget, thread count, repeats or brick proxies (--no-proxies, --proxy-res); --any-hit writes bools;
// statistics are printed and written as JSON; --subtree-dir saves bvh bricks
// and a later run loads them (same answer, no builds); bad rays files, invalid rays (with --strict), unknown
// options, a missing store and a cache too small for one brick are errors that name what is wrong.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/io/npy.h"
#include "core/query/query_engine.h"
#include "core/store/scene_store.h"
#include "tests/support/json_fields.h"
#include "tests/support/subprocess.h"
#include "tests/support/test_paths.h"
#include "tests/support/test_rays.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::contains;
using testing::count_of;
using testing::json_uint;
using testing::outcore_binary;
using testing::run_subprocess;
using testing::SubprocessOptions;
using testing::SubprocessResult;
using testing::TempDir;
using testing::write_text_file;

constexpr std::size_t kRayCount = 3000;

SubprocessResult outcore(std::vector<std::string> args) {
  return testing::run_outcore(std::move(args), std::chrono::milliseconds(60'000));
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return std::move(s).str();
}

// ---- a small JSON checker and field reader ----------------------------------------

class JsonChecker {
 public:
  explicit JsonChecker(const std::string& text) : s_(text) {}
  bool valid() {
    skip();
    if (!value()) return false;
    skip();
    return i_ == s_.size();
  }

 private:
  void skip() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  bool literal(const char* word) {
    const std::size_t n = std::strlen(word);
    if (s_.compare(i_, n, word) != 0) return false;
    i_ += n;
    return true;
  }
  bool string() {
    if (s_[i_] != '"') return false;
    for (++i_; i_ < s_.size(); ++i_) {
      const char c = s_[i_];
      if (c == '"') {
        ++i_;
        return true;
      }
      if (static_cast<unsigned char>(c) < 0x20) return false;
      if (c == '\\') {
        if (++i_ >= s_.size() || !std::strchr("\"\\/bfnrtu", s_[i_])) return false;
      }
    }
    return false;
  }
  bool number() {
    const std::size_t start = i_;
    if (s_[i_] == '-') ++i_;
    if (i_ >= s_.size() || !std::isdigit(static_cast<unsigned char>(s_[i_]))) return false;
    if (s_[i_] == '0' && i_ + 1 < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_ + 1])))
      return false;
    while (i_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_]))) ++i_;
    if (i_ < s_.size() && s_[i_] == '.') {
      ++i_;
      if (i_ >= s_.size() || !std::isdigit(static_cast<unsigned char>(s_[i_]))) return false;
      while (i_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_]))) ++i_;
    }
    if (i_ < s_.size() && (s_[i_] == 'e' || s_[i_] == 'E')) {
      ++i_;
      if (i_ < s_.size() && (s_[i_] == '+' || s_[i_] == '-')) ++i_;
      if (i_ >= s_.size() || !std::isdigit(static_cast<unsigned char>(s_[i_]))) return false;
      while (i_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_]))) ++i_;
    }
    return i_ > start;
  }
  bool value() {
    if (++depth_ > 64 || i_ >= s_.size()) return false;
    bool ok = false;
    const char c = s_[i_];
    if (c == '{' || c == '[') {
      const char close = c == '{' ? '}' : ']';
      ++i_;
      skip();
      if (i_ < s_.size() && s_[i_] == close) {
        ++i_;
        ok = true;
      } else {
        while (true) {
          if (c == '{') {
            if (i_ >= s_.size() || !string()) break;
            skip();
            if (i_ >= s_.size() || s_[i_++] != ':') break;
            skip();
          }
          if (!value()) break;
          skip();
          if (i_ >= s_.size()) break;
          if (s_[i_] == ',') {
            ++i_;
            skip();
            continue;
          }
          if (s_[i_] == close) {
            ++i_;
            ok = true;
          }
          break;
        }
      }
    } else if (c == '"') {
      ok = string();
    } else if (c == 't' || c == 'f' || c == 'n') {
      ok = literal("true") || literal("false") || literal("null");
    } else {
      ok = number();
    }
    --depth_;
    return ok;
  }

  const std::string& s_;
  std::size_t i_ = 0;
  int depth_ = 0;
};

bool valid_json(const std::string& text) {
  return JsonChecker(text).valid();
}

// ---- the shared scene, rays and in-process answers ---------------------------------

std::vector<Hit> reference_hits(const std::string& store, const std::vector<Ray>& rays) {
  auto engine = QueryEngine::open(store, EngineOptions{});
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  if (!engine.ok()) return {};
  std::vector<Hit> hits(rays.size());
  const Status status = (*engine)->intersect(rays, hits, QueryOptions{});
  EXPECT_TRUE(status.ok()) << status.to_string();
  return hits;
}

// The header numpy.save writes for a float32 array of shape (rows, columns).
std::string f4_npy_header(const std::string& rows, int columns) {
  std::string dict =
      "{'descr': '<f4', 'fortran_order': False, 'shape': (" + rows + ", " + std::to_string(columns) + "), }";
  dict.append(21 - std::min<std::size_t>(rows.size(), 21), ' ');
  const std::size_t hlen = dict.size() + 1;
  const std::size_t pad = 64 - (10 + hlen) % 64;
  std::string out("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>((hlen + pad) & 0xff);
  out += static_cast<char>((hlen + pad) >> 8);
  return out + dict + std::string(pad, ' ') + "\n";
}

// A (N,6) float32 .npy as numpy.save writes it.
std::string six_column_npy(const std::vector<Ray>& rays) {
  std::string out = f4_npy_header(std::to_string(rays.size()), 6);
  for (const Ray& r : rays) {
    const float row[6] = {r.origin.x, r.origin.y, r.origin.z, r.direction.x, r.direction.y, r.direction.z};
    out.append(reinterpret_cast<const char*>(row), sizeof row);
  }
  return out;
}

class TraceCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    store_ = dir_->file("scene");
    const SubprocessResult packed = outcore({"pack", "gen:sphere?level=3", "gen:torus?cx=3", "-o", store_,
                                             "--brick-tris", "200", "-q", "--no-sync"});
    ASSERT_TRUE(packed.succeeded()) << packed.describe();
    auto store = SceneStore::open(store_);
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    brick_count_ = (*store)->brick_count();
    rays_ = new std::vector<Ray>(testing::make_test_rays((*store)->manifest().bounds, kRayCount, 1234));
    rays_path_ = dir_->file("rays.npy");
    ASSERT_TRUE(write_rays_npy(rays_path_, *rays_).ok());
    hits_ = new std::vector<Hit>(reference_hits(store_, *rays_));
  }
  static void TearDownTestSuite() {
    delete hits_;
    delete rays_;
    delete dir_;
    hits_ = nullptr;
    rays_ = nullptr;
    dir_ = nullptr;
  }

  void SetUp() override {
    ASSERT_NE(hits_, nullptr);
    ASSERT_EQ(hits_->size(), kRayCount) << "suite setup failed";
  }

  // Runs `outcore trace` on the shared store; returns the result.
  static SubprocessResult trace(const std::string& rays, const std::string& out,
                                std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"trace", store_, "--rays", rays, "-o", out};
    args.insert(args.end(), extra.begin(), extra.end());
    return outcore(args);
  }

  // The data bytes of a hits file (after checking its header).
  static std::string hits_data(const std::string& path) {
    const std::string bytes = read_bytes(path);
    const auto header = parse_npy_header(bytes, path);
    EXPECT_TRUE(header.ok()) << header.status().to_string();
    if (!header.ok()) return {};
    EXPECT_EQ(header->descr, kHitsNpyDescr);
    EXPECT_EQ(header->shape.size(), 1u);
    return bytes.substr(header->data_offset);
  }

  static std::string reference_bytes(const std::vector<Hit>& hits) {
    return std::string(reinterpret_cast<const char*>(hits.data()), hits.size() * sizeof(Hit));
  }

  // Runs trace with `extra` and expects the hits file to be the reference, bit for bit.
  void expect_reference_answer(const std::vector<std::string>& extra) {
    TempDir out;
    const std::string hits = out.file("hits.npy");
    const SubprocessResult r = trace(rays_path_, hits, extra);
    ASSERT_TRUE(r.succeeded()) << r.describe();
    const std::string data = hits_data(hits);
    ASSERT_EQ(data.size(), kRayCount * sizeof(Hit));
    const std::string want = reference_bytes(*hits_);
    if (data != want) {
      std::size_t first = 0;
      while (data[first] == want[first]) ++first;
      FAIL() << "hits differ from the in-process answer, first at ray " << first / sizeof(Hit);
    }
  }

  static TempDir* dir_;
  static std::string store_;
  static std::string rays_path_;
  static std::vector<Ray>* rays_;
  static std::vector<Hit>* hits_;
  static uint32_t brick_count_;
};

TempDir* TraceCli::dir_ = nullptr;
std::string TraceCli::store_;
std::string TraceCli::rays_path_;
std::vector<Ray>* TraceCli::rays_ = nullptr;
std::vector<Hit>* TraceCli::hits_ = nullptr;
uint32_t TraceCli::brick_count_ = 0;

// ---- answers ------------------------------------------------------------------------

TEST_F(TraceCli, ClosestHitsEqualTheInProcessAnswerBitwise) {
  // The scene and rays exercise hits on both inputs, misses and several bricks.
  std::size_t hit_count = 0, on_sphere = 0, on_torus = 0;
  for (const Hit& h : *hits_) {
    hit_count += h.is_hit();
    on_sphere += h.is_hit() && h.geometry_id == 0;
    on_torus += h.is_hit() && h.geometry_id == 1;
  }
  ASSERT_GT(on_sphere, 50u);
  ASSERT_GT(on_torus, 50u);
  ASSERT_GT(kRayCount - hit_count, 50u);
  ASSERT_GT(brick_count_, 8u);

  expect_reference_answer({});
}

TEST_F(TraceCli, ReadsSixColumnRaysWithDefaultTnearAndTfar) {
  std::vector<Ray> unlimited = *rays_;
  for (Ray& r : unlimited) r = Ray{r.origin, r.direction};
  const std::vector<Hit> want = reference_hits(store_, unlimited);
  TempDir out;
  write_text_file(out.file("rays6.npy"), six_column_npy(unlimited));
  const SubprocessResult r = trace(out.file("rays6.npy"), out.file("hits.npy"));
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(hits_data(out.file("hits.npy")) == reference_bytes(want)) << "(N,6) rays answered differently";
  // Limits matter: the (N,8) answer with tnear/tfar differs on some rays.
  EXPECT_FALSE(reference_bytes(want) == reference_bytes(*hits_));
}

TEST_F(TraceCli, AnyHitWritesBoolsEqualToHitExists) {
  TempDir out;
  const std::string path = out.file("occluded.npy");
  const SubprocessResult r = trace(rays_path_, path, {"--any-hit"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const auto flags = read_bools_npy(path);
  ASSERT_TRUE(flags.ok()) << flags.status().to_string();
  ASSERT_EQ(flags->size(), kRayCount);
  for (std::size_t i = 0; i < kRayCount; ++i) {
    ASSERT_EQ((*flags)[i], (*hits_)[i].is_hit() ? 1 : 0) << "ray " << i;
  }
}

TEST_F(TraceCli, SameAnswerWithoutReordering) {
  expect_reference_answer({"--no-reorder"});
}

// On a store of a few bricks the warm run of a repeat sweeps ray chunks
// through the resident bricks (each taken from the cache once); with the
// flag it queues them (one acquisition per 512-ray chunk). Same hits.
TEST_F(TraceCli, TheInCacheSweepAndTheQueuesGiveTheSameHits) {
  TempDir out;
  const std::string store = out.file("few");
  const SubprocessResult packed =
      outcore({"pack", "gen:sphere?level=5", "-o", store, "--brick-tris", "4000", "-q", "--no-sync"});
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  const auto few = SceneStore::open(store);
  ASSERT_TRUE(few.ok()) << few.status().to_string();
  const uint64_t bricks = (*few)->brick_count();
  ASSERT_GT(bricks, 1u);
  ASSERT_LE(bricks, 16u);
  const std::string rays = out.file("rays.npy");
  ASSERT_TRUE(write_rays_npy(rays, testing::make_test_rays((*few)->manifest().bounds, 4000, 77)).ok());
  const std::string swept_json = out.file("swept.json"), queued_json = out.file("queued.json");
  const SubprocessResult swept = outcore({"trace", store, "--rays", rays, "-o", out.file("swept.npy"),
                                          "--repeat", "2", "--stats-json", swept_json});
  ASSERT_TRUE(swept.succeeded()) << swept.describe();
  const SubprocessResult queued =
      outcore({"trace", store, "--rays", rays, "-o", out.file("queued.npy"), "--repeat", "2",
               "--no-in-cache-sweep", "--stats-json", queued_json});
  ASSERT_TRUE(queued.succeeded()) << queued.describe();
  EXPECT_EQ(read_bytes(out.file("swept.npy")), read_bytes(out.file("queued.npy")));
  const std::string swept_stats = read_bytes(swept_json), queued_stats = read_bytes(queued_json);
  EXPECT_LE(json_uint(swept_stats, "brick_acquisitions", 1), bricks);
  EXPECT_GT(json_uint(queued_stats, "brick_acquisitions", 1), bricks);
  EXPECT_EQ(json_uint(swept_stats, "brick_visits", 1), json_uint(queued_stats, "brick_visits", 1));
  EXPECT_EQ(json_uint(swept_stats, "rays_hit", 1), json_uint(queued_stats, "rays_hit", 1));
}

TEST_F(TraceCli, SameAnswerWithATinyCache) {
  TempDir out;
  const std::string json = out.file("stats.json");
  expect_reference_answer({"--cache-mb", "1", "--stats-json", json});
  EXPECT_EQ(json_uint(read_bytes(json), "cache_budget_bytes"), uint64_t{1} << 20) << "--cache-mb not applied";
}

TEST_F(TraceCli, SameAnswerWithOneThread) {
  expect_reference_answer({"--threads", "1"});
}

TEST_F(TraceCli, SameAnswerWhenRepeated) {
  expect_reference_answer({"--repeat", "3"});
}

TEST_F(TraceCli, SameAnyHitAnswerWithoutReorderingOnATinyCache) {
  TempDir out;
  const SubprocessResult r = trace(rays_path_, out.file("a.npy"),
                                   {"--any-hit", "--no-reorder", "--cache-mb", "1", "--threads", "1"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const auto flags = read_bools_npy(out.file("a.npy"));
  ASSERT_TRUE(flags.ok()) << flags.status().to_string();
  ASSERT_EQ(flags->size(), kRayCount);
  for (std::size_t i = 0; i < kRayCount; ++i)
    ASSERT_EQ((*flags)[i], (*hits_)[i].is_hit() ? 1 : 0) << "ray " << i;
}

// ---- statistics -------------------------------------------------------------------

TEST_F(TraceCli, StatsPrintsRaysAndBuilds) {
  TempDir out;
  const SubprocessResult r = trace(rays_path_, out.file("h.npy"), {"--stats"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stdout_text, "rays " + std::to_string(kRayCount))) << r.stdout_text;
  EXPECT_TRUE(contains(r.stdout_text, "builds")) << r.stdout_text;

  const SubprocessResult quiet = trace(rays_path_, out.file("h2.npy"));
  ASSERT_TRUE(quiet.succeeded()) << quiet.describe();
  EXPECT_FALSE(contains(quiet.stdout_text, "builds")) << "statistics printed without --stats";

  const SubprocessResult repeated = trace(rays_path_, out.file("h3.npy"), {"--stats", "--repeat", "3"});
  ASSERT_TRUE(repeated.succeeded()) << repeated.describe();
  EXPECT_EQ(count_of(repeated.stdout_text, "builds"), 3u) << repeated.stdout_text;
}

TEST_F(TraceCli, StatsJsonHasTheCounters) {
  std::size_t hit_count = 0;
  for (const Hit& h : *hits_) hit_count += h.is_hit();
  TempDir out;
  const std::string path = out.file("stats.json");
  const SubprocessResult r = trace(rays_path_, out.file("h.npy"), {"--stats-json", path});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const std::string json = read_bytes(path);
  ASSERT_TRUE(valid_json(json)) << json;
  EXPECT_EQ(json_uint(json, "rays"), kRayCount);
  EXPECT_EQ(json_uint(json, "invalid_rays"), 0u);
  EXPECT_EQ(json_uint(json, "rays_hit"), hit_count);
  const uint64_t builds = json_uint(json, "brick_builds");
  EXPECT_GT(builds, 0u);
  EXPECT_LE(builds, brick_count_);
  const uint64_t cache_hits = json_uint(json, "cache_hits");
  const uint64_t cache_misses = json_uint(json, "cache_misses");
  EXPECT_EQ(cache_hits + cache_misses, json_uint(json, "brick_acquisitions"));
  // Cold cache with room for every brick: every brick is built once, on its miss.
  EXPECT_EQ(cache_misses, builds);
  const uint64_t peak = json_uint(json, "peak_bytes_resident");
  EXPECT_GT(peak, 0u);
  EXPECT_LE(peak, json_uint(json, "cache_budget_bytes"));
  EXPECT_EQ(json_uint(json, "cache_budget_bytes"), uint64_t{1024} << 20);
}

// ---- brick proxies ------------------------------------------------------------------

TEST_F(TraceCli, SameAnswerWithoutProxiesOrAtAnotherProxyResolution) {
  expect_reference_answer({"--no-proxies"});
  expect_reference_answer({"--proxy-res", "8"});
  expect_reference_answer({"--proxy-res", "64", "--no-reorder"});
  expect_reference_answer({"--no-proxies", "--cache-mb", "1"});
}

TEST_F(TraceCli, StatsReportProxySkipsBytesAndTimeAndNothingWithoutProxies) {
  TempDir out;
  const std::string on_json = out.file("on.json"), off_json = out.file("off.json");
  // Ray by ray: every visit is tested (with reordering and a budget that
  // holds the scene, only bricks about to be built are).
  const SubprocessResult on =
      trace(rays_path_, out.file("h.npy"), {"--stats", "--no-reorder", "--stats-json", on_json});
  ASSERT_TRUE(on.succeeded()) << on.describe();
  EXPECT_TRUE(contains(on.stdout_text, "brick visits skipped")) << on.stdout_text;
  EXPECT_TRUE(contains(on.stdout_text, "proxies: resolution 32")) << on.stdout_text;
  const SubprocessResult off = trace(rays_path_, out.file("h2.npy"),
                                     {"--stats", "--no-reorder", "--no-proxies", "--stats-json", off_json});
  ASSERT_TRUE(off.succeeded()) << off.describe();
  EXPECT_TRUE(contains(off.stdout_text, "proxies: off")) << off.stdout_text;
  const std::string a = read_bytes(on_json), b = read_bytes(off_json);
  ASSERT_TRUE(valid_json(a)) << a;
  const uint64_t skipped = json_uint(a, "bricks_skipped_by_proxy");
  EXPECT_GT(skipped, 0u) << a;
  EXPECT_GT(json_uint(a, "proxy_bytes"), 0u) << a;
  EXPECT_TRUE(contains(a, "\"proxy\":")) << a;
  EXPECT_EQ(json_uint(b, "bricks_skipped_by_proxy"), 0u) << b;
  EXPECT_EQ(json_uint(b, "proxy_bytes"), 0u) << b;
  EXPECT_EQ(json_uint(a, "brick_visits") + skipped, json_uint(b, "brick_visits"));
}

TEST_F(TraceCli, StatsJsonOfRepeatsIsAnArrayWithAWarmCache) {
  TempDir out;
  const std::string path = out.file("stats.json");
  const SubprocessResult r = trace(rays_path_, out.file("h.npy"), {"--stats-json", path, "--repeat", "3"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const std::string json = read_bytes(path);
  ASSERT_TRUE(valid_json(json)) << json;
  ASSERT_EQ(json.front(), '[') << json;
  ASSERT_EQ(count_of(json, "\"brick_builds\""), 3u) << json;
  EXPECT_GT(json_uint(json, "brick_builds", 0), 0u);
  for (int run = 0; run < 3; ++run) EXPECT_EQ(json_uint(json, "rays", run), kRayCount) << "run " << run;
  for (int run = 1; run < 3; ++run) {
    EXPECT_EQ(json_uint(json, "brick_builds", run), 0u) << "run " << run << " rebuilt bricks";
    EXPECT_EQ(json_uint(json, "cache_misses", run), 0u) << "run " << run;
    EXPECT_GT(json_uint(json, "cache_hits", run), 0u) << "run " << run;
  }
}

// ---- invalid rays -----------------------------------------------------------------

TEST_F(TraceCli, NanOriginRayIsCountedInvalidAndAnsweredAsAMiss) {
  // The first ray that hits, so that its becoming a miss shows.
  std::size_t kBad = 1;
  while (kBad < kRayCount && !(*hits_)[kBad].is_hit()) ++kBad;
  ASSERT_LT(kBad, kRayCount);
  std::vector<Ray> rays = *rays_;
  rays[kBad].origin.y = std::numeric_limits<float>::quiet_NaN();
  TempDir out;
  const std::string rays_path = out.file("nan_rays.npy");
  ASSERT_TRUE(write_rays_npy(rays_path, rays).ok());

  const std::string json_path = out.file("stats.json");
  const SubprocessResult r = trace(rays_path, out.file("h.npy"), {"--stats-json", json_path});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  const std::string json = read_bytes(json_path);
  EXPECT_EQ(json_uint(json, "invalid_rays"), 1u) << json;
  EXPECT_EQ(json_uint(json, "rays"), kRayCount) << json;
  const auto hits = read_hits_npy(out.file("h.npy"));
  ASSERT_TRUE(hits.ok()) << hits.status().to_string();
  ASSERT_EQ(hits->size(), kRayCount);
  const Hit miss;
  EXPECT_EQ(std::memcmp(&(*hits)[kBad], &miss, sizeof(Hit)), 0) << "the NaN ray is not a clean miss";
  for (std::size_t i = 0; i < kRayCount; ++i) {
    if (i == kBad) continue;
    ASSERT_EQ(std::memcmp(&(*hits)[i], &(*hits_)[i], sizeof(Hit)), 0) << "ray " << i;
  }

  const SubprocessResult strict = trace(rays_path, out.file("strict.npy"), {"--strict"});
  EXPECT_NE(strict.exit_code, 0) << strict.describe();
  EXPECT_EQ(strict.term_signal, 0) << strict.describe();
  EXPECT_TRUE(contains(strict.stderr_text, "ray " + std::to_string(kBad))) << strict.stderr_text;
  EXPECT_TRUE(contains(strict.stderr_text, "NaN")) << strict.stderr_text;
  EXPECT_FALSE(fs::exists(out.file("strict.npy"))) << "output written despite the error";

  const SubprocessResult strict_any = trace(rays_path, out.file("strict_any.npy"), {"--strict", "--any-hit"});
  EXPECT_NE(strict_any.exit_code, 0) << strict_any.describe();
  EXPECT_TRUE(contains(strict_any.stderr_text, "ray " + std::to_string(kBad))) << strict_any.stderr_text;
}

// ---- errors -----------------------------------------------------------------------

// A failing trace: non-zero exit (not a crash), stderr mentions every one of
// `mentions`, and no output file is left.
void expect_trace_fails(const SubprocessResult& r, const std::string& output,
                        const std::vector<std::string>& mentions) {
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_NE(r.exit_code, 0) << r.describe();
  EXPECT_EQ(r.term_signal, 0) << r.describe();
  for (const std::string& m : mentions) {
    EXPECT_TRUE(contains(r.stderr_text, m)) << "no '" << m << "' in:\n" << r.stderr_text;
  }
  EXPECT_FALSE(fs::exists(output)) << "output written despite the error";
}

TEST_F(TraceCli, BadRaysFilesAreRejectedNamingFileAndProblem) {
  TempDir out;
  const std::string good = read_bytes(rays_path_);
  const auto header = parse_npy_header(good, rays_path_);
  ASSERT_TRUE(header.ok());
  const std::string dict = good.substr(10, header->data_offset - 10);

  auto with_dict = [&](const std::string& from, const std::string& to) {
    std::string d = dict;
    const auto pos = d.find(from);
    EXPECT_NE(pos, std::string::npos) << from << " not in " << d;
    d.replace(pos, from.size(), to);
    return good.substr(0, 10) + d + good.substr(header->data_offset);
  };
  const std::string n = std::to_string(kRayCount);

  const std::string f8 = out.file("float64_rays.npy");
  write_text_file(f8, with_dict("'<f4'", "'<f8'") + std::string(kRayCount * 8 * 4, '\0'));
  expect_trace_fails(trace(f8, out.file("h.npy")), out.file("h.npy"), {f8, "'<f8'", "float32"});

  const std::string five = out.file("five_column_rays.npy");
  write_text_file(
      five, with_dict("(" + n + ", 8)", "(" + n + ", 5)").substr(0, header->data_offset + kRayCount * 20));
  expect_trace_fails(trace(five, out.file("h.npy")), out.file("h.npy"), {five, "(" + n + ", 5)"});

  const std::string cut = out.file("truncated_rays.npy");
  write_text_file(cut, good.substr(0, good.size() - 10));
  expect_trace_fails(trace(cut, out.file("h.npy")), out.file("h.npy"), {cut, "truncated"});

  const std::string absent = out.file("absent_rays.npy");
  expect_trace_fails(trace(absent, out.file("h.npy")), out.file("h.npy"), {absent});

  // Any-hit reads rays the same way.
  expect_trace_fails(trace(cut, out.file("h.npy"), {"--any-hit"}), out.file("h.npy"), {cut, "truncated"});
}

TEST_F(TraceCli, UnknownPolicyAccelAndAccelOptionAreRejectedByName) {
  TempDir out;
  const std::string h = out.file("h.npy");
  expect_trace_fails(trace(rays_path_, h, {"--policy", "no_such_policy"}), h, {"no_such_policy"});
  expect_trace_fails(trace(rays_path_, h, {"--brick-accel", "no_such_accel"}), h, {"no_such_accel"});
  expect_trace_fails(trace(rays_path_, h, {"--accel-opt", "no_such_key=1"}), h, {"no_such_key"});
  expect_trace_fails(trace(rays_path_, h, {"--brick-accel", "embree", "--accel-opt", "quality=extreme"}), h,
                     {"quality", "extreme"});
  expect_trace_fails(trace(rays_path_, h, {"--accel-opt", "noequals"}), h, {"noequals"});
}

TEST_F(TraceCli, MissingStoreIsAnError) {
  TempDir out;
  const std::string missing = out.file("no_scene");
  const std::string h = out.file("h.npy");
  const SubprocessResult r = outcore({"trace", missing, "--rays", rays_path_, "-o", h});
  expect_trace_fails(r, h, {missing});
}

TEST_F(TraceCli, CacheSmallerThanOneBrickIsAnErrorNamingTheBrick) {
  // One brick of 20480 triangles cannot be built within 1 MiB.
  TempDir out;
  const std::string big = out.file("big_scene");
  const SubprocessResult packed =
      outcore({"pack", "gen:sphere?level=5", "-o", big, "--brick-tris", "30000", "-q", "--no-sync"});
  ASSERT_TRUE(packed.succeeded()) << packed.describe();
  const std::string h = out.file("h.npy");
  const SubprocessResult r = outcore({"trace", big, "--rays", rays_path_, "-o", h, "--cache-mb", "1"});
  expect_trace_fails(r, h, {"budget"});
  EXPECT_TRUE(std::regex_search(r.stderr_text, std::regex("brick [0-9]+"))) << r.stderr_text;

  // With room it answers.
  const SubprocessResult ok = outcore({"trace", big, "--rays", rays_path_, "-o", h, "--cache-mb", "64"});
  EXPECT_TRUE(ok.succeeded()) << ok.describe();
}

// A header whose shape's byte size overflows 64 bits is a clean error, not a
// crash (an uncaught std::length_error from a huge allocation).
TEST_F(TraceCli, RaysHeaderWithOverflowingShapeIsAnErrorNotACrash) {
  TempDir out;
  // 2^61 rows * 8 columns * 4 bytes = 2^66 bytes, which wraps to 0 in 64 bits.
  const std::string head = f4_npy_header("2305843009213693952", 8);
  const std::string path = out.file("huge_rays.npy");
  write_text_file(path, head);
  const std::string h = out.file("h.npy");
  expect_trace_fails(trace(path, h), h, {path});
}

// --cache-mb is MiB; a value whose byte count does not fit 64 bits must be
// refused, not wrapped around to a different (here: 1 MiB) budget.
TEST_F(TraceCli, CacheMbTooLargeForBytesIsRejected) {
  TempDir out;
  const std::string json = out.file("stats.json");
  // (2^44 + 1) MiB = 2^64 + 2^20 bytes, which wraps to 1 MiB.
  const SubprocessResult r =
      trace(rays_path_, out.file("h.npy"), {"--cache-mb", "17592186044417", "--stats-json", json});
  if (r.exit_code == 0) {
    ADD_FAILURE() << "accepted --cache-mb 17592186044417; budget used: "
                  << json_uint(read_bytes(json), "cache_budget_bytes") << " bytes";
  } else {
    EXPECT_TRUE(contains(r.stderr_text, "cache")) << r.stderr_text;
  }
}

TEST_F(TraceCli, InfoShowsTheCachedProxiesAndACorruptFile) {
  // The suite's in-process engine wrote proxies.bin on first open.
  SubprocessResult r = outcore({"info", store_});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stdout_text, "proxies       valid: resolution 32")) << r.stdout_text;
  r = outcore({"info", store_, "--json"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stdout_text, "\"proxies\":{\"state\":\"valid\",\"resolution\":32")) << r.stdout_text;
  // A corrupted copy: info says so, and the next trace rebuilds it.
  TempDir copy_dir;
  const std::string copy = copy_dir.file("scene");
  fs::copy(store_, copy, fs::copy_options::recursive);
  const std::string proxies = copy + "/proxies.bin";
  std::string bytes = read_bytes(proxies);
  bytes[bytes.size() - 5] ^= 0x20;
  write_text_file(proxies, bytes);
  r = outcore({"info", copy});
  EXPECT_TRUE(contains(r.stdout_text, "proxies       corrupt")) << r.stdout_text;
  r = outcore({"trace", copy, "--rays", rays_path_, "-o", copy_dir.file("h.npy"), "--stats"});
  ASSERT_TRUE(r.succeeded()) << r.describe();
  EXPECT_TRUE(contains(r.stdout_text, "built and written to proxies.bin")) << r.stdout_text;
  EXPECT_TRUE(hits_data(copy_dir.file("h.npy")) == reference_bytes(*hits_));
  r = outcore({"info", copy});
  EXPECT_TRUE(contains(r.stdout_text, "proxies       valid")) << r.stdout_text;
}

TEST_F(TraceCli, BadProxyOptionsAreRejectedByName) {
  TempDir out;
  const std::string h = out.file("h.npy");
  expect_trace_fails(trace(rays_path_, h, {"--proxy-res", "0"}), h, {"--proxy-res", "got 0"});
  expect_trace_fails(trace(rays_path_, h, {"--proxy-res", "100000"}), h, {"--proxy-res", "100000"});
  expect_trace_fails(trace(rays_path_, h, {"--proxy-res", "many"}), h, {"--proxy-res"});
  expect_trace_fails(trace(rays_path_, h, {"--no-proxies", "--proxy-res", "8"}), h, {"--no-proxies"});
}

// ---- subtree tier -------------------------------------------------------------------

TEST_F(TraceCli, SubtreeDirGivesTheSameAnswerAndALaterRunLoadsInsteadOfBuilding) {
  TempDir out;
  const std::string tier = out.file("subtrees");
  const SubprocessResult plain = trace(rays_path_, out.file("plain.npy"), {"--brick-accel", "bvh"});
  ASSERT_TRUE(plain.succeeded()) << plain.describe();
  const std::string want = hits_data(out.file("plain.npy"));
  ASSERT_EQ(want.size(), kRayCount * sizeof(Hit));
  for (int run = 0; run < 2; ++run) {
    const std::string json = out.file("stats" + std::to_string(run) + ".json");
    const std::string hits = out.file("hits" + std::to_string(run) + ".npy");
    const SubprocessResult r = trace(rays_path_, hits,
                                     {"--brick-accel", "bvh", "--cache-mb", "1", "--subtree-dir", tier,
                                      "--subtree-dir-mb", "64", "--stats", "--stats-json", json});
    ASSERT_TRUE(r.succeeded()) << r.describe();
    EXPECT_TRUE(hits_data(hits) == want) << "run " << run << " answered differently with the tier";
    EXPECT_TRUE(contains(r.stdout_text, "subtree tier:")) << r.stdout_text;
    const std::string stats = read_bytes(json);
    ASSERT_TRUE(valid_json(stats)) << stats;
    EXPECT_EQ(json_uint(stats, "subtree_rejects"), 0u);
    const uint64_t mapped_nothing =
        json_uint(stats, "subtree_loads_kept") + json_uint(stats, "subtree_loads_recycled");
    EXPECT_LE(mapped_nothing, json_uint(stats, "subtree_loads")) << stats;
    if (run == 0) {
      // The process that wrote the files keeps their copies: every reload
      // reads into its own or another evicted brick's.
      EXPECT_EQ(mapped_nothing, json_uint(stats, "subtree_loads")) << stats;
      EXPECT_GT(json_uint(stats, "subtree_writes"), 0u);
      EXPECT_EQ(json_uint(stats, "subtree_writes"), json_uint(stats, "brick_builds"));
    } else {
      EXPECT_EQ(json_uint(stats, "brick_builds"), 0u) << stats;
      EXPECT_EQ(json_uint(stats, "subtree_loads"), json_uint(stats, "cache_misses")) << stats;
      EXPECT_GT(json_uint(stats, "subtree_bytes_read"), 0u);
    }
  }
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(tier)) files += entry.path().extension() == ".subtree";
  EXPECT_GT(files, 0u);
  EXPECT_LE(files, brick_count_);
}

TEST_F(TraceCli, SubtreeDirIsRejectedWithoutBvhNamingTheOption) {
  TempDir out;
  const std::string h = out.file("h.npy");
  const std::string tier = out.file("subtrees");
  expect_trace_fails(trace(rays_path_, h, {"--brick-accel", "embree", "--subtree-dir", tier}), h,
                     {"--subtree-dir", "bvh", "embree"});
  expect_trace_fails(trace(rays_path_, h, {"--reference", "--subtree-dir", tier}), h, {"--subtree-dir"});
  expect_trace_fails(trace(rays_path_, h, {"--brick-accel", "bvh", "--subtree-dir-mb", "8"}), h,
                     {"--subtree-dir-mb needs --subtree-dir"});
  expect_trace_fails(trace(rays_path_, h, {"--brick-accel", "bvh", "--subtree-release-batch-mb", "0"}), h,
                     {"--subtree-release-batch-mb needs --subtree-dir"});
  EXPECT_FALSE(fs::exists(tier)) << "nothing created on a rejected command line";
  const SubprocessResult serve =
      outcore({"serve", store_, "--listen", "127.0.0.1:0", "--brick-accel", "embree", "--subtree-dir", tier});
  EXPECT_FALSE(serve.succeeded());
  EXPECT_TRUE(contains(serve.stderr_text, "--subtree-dir needs --brick-accel bvh")) << serve.describe();
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
