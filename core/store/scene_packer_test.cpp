#include "core/store/scene_packer.h"

#include <unistd.h>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/source/source_factory.h"
#include "core/store/scene_store.h"
#include "core/util/cancellation.h"
#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;
using testing::model_path;
using testing::TempDir;
using testing::write_text_file;

// Up to this many problems are spelled out; the rest are only counted, so a
// broken pack of a million triangles does not print a million lines.
class Problems {
 public:
  void add(const std::string& what) {
    if (count_++ < 10) text_ += "  " + what + "\n";
  }
  uint64_t count() const { return count_; }
  std::string report() const { return std::to_string(count_) + " problem(s):\n" + text_; }

 private:
  uint64_t count_ = 0;
  std::string text_;
};

std::string id_name(uint32_t g, uint64_t p) {
  return "(" + std::to_string(g) + ", " + std::to_string(p) + ")";
}

// Checks the whole store against its inputs, streamed again independently:
// every input triangle is in exactly one brick, bit for bit, under its own
// (geometry_id, primitive_id); bricks are non-empty, at most brick_triangles,
// and their recorded bounds are exactly their triangles' bounds; the upper
// hierarchy has the bricks as its leaves, each once, and every node contains
// its children; the manifest's and the summary's counts are right.
void expect_round_trip(const std::string& store_dir, const std::vector<std::string>& inputs,
                       uint32_t brick_triangles, const PackSummary& summary) {
  auto opened = SceneStore::open(store_dir);
  ASSERT_TRUE(opened.ok()) << opened.status().to_string();
  const SceneStore& store = **opened;
  const Manifest& m = store.manifest();
  ASSERT_EQ(m.inputs.size(), inputs.size());
  for (size_t g = 0; g < inputs.size(); ++g) EXPECT_EQ(m.inputs[g].spec, inputs[g]);

  // Every stored triangle, indexed by its ids.
  std::vector<std::vector<Triangle>> stored(inputs.size());
  std::vector<std::vector<uint8_t>> seen(inputs.size());
  for (size_t g = 0; g < inputs.size(); ++g) {
    ASSERT_LT(m.inputs[g].triangle_count, 100'000'000u) << "implausible count for input " << g;
    stored[g].resize(m.inputs[g].triangle_count);
    seen[g].assign(m.inputs[g].triangle_count, 0);
  }
  Problems problems;
  Aabb all_bricks;
  uint32_t largest_brick = 0;
  BrickData brick;
  for (uint32_t b = 0; b < store.brick_count(); ++b) {
    const Status loaded = store.load_brick(b, brick);
    ASSERT_TRUE(loaded.ok()) << loaded.to_string();
    const BrickRecord& record = m.bricks[b];
    const std::string name = "brick " + std::to_string(b);
    EXPECT_EQ(brick.brick_id, b);
    ASSERT_EQ(brick.triangles.size(), record.triangle_count) << name;
    ASSERT_EQ(brick.ids.size(), record.triangle_count) << name;
    EXPECT_GT(record.triangle_count, 0u) << name;
    EXPECT_LE(record.triangle_count, brick_triangles) << name;
    largest_brick = std::max(largest_brick, record.triangle_count);
    Aabb bounds;
    for (size_t i = 0; i < brick.triangles.size(); ++i) {
      const Triangle& t = brick.triangles[i];
      const TriangleId id = brick.ids[i];
      bounds.extend(t.bounds());
      if (!record.bounds.contains(t.bounds()))
        problems.add(name + ": triangle " + std::to_string(i) + " outside");
      if (id.geometry_id >= inputs.size() || id.primitive_id >= stored[id.geometry_id].size()) {
        problems.add(name + " holds unknown ids " + id_name(id.geometry_id, id.primitive_id));
        continue;
      }
      if (seen[id.geometry_id][id.primitive_id]++) {
        problems.add("ids " + id_name(id.geometry_id, id.primitive_id) + " stored twice (again in " + name +
                     ")");
      }
      stored[id.geometry_id][id.primitive_id] = t;
    }
    EXPECT_EQ(bounds, record.bounds) << name << ": recorded bounds are not its triangles' bounds";
    all_bricks.extend(record.bounds);
  }

  // Stream every input again and compare.
  uint64_t total = 0, degenerate_total = 0;
  for (size_t g = 0; g < inputs.size(); ++g) {
    auto source = open_triangle_source(inputs[g]);
    ASSERT_TRUE(source.ok()) << source.status().to_string();
    uint64_t k = 0, degenerate = 0;
    CallbackSink sink([&](std::span<const Triangle> batch) {
      for (const Triangle& t : batch) {
        degenerate += t.is_degenerate();
        if (k >= stored[g].size()) {
          problems.add("input " + std::to_string(g) + " has more triangles than the manifest records");
        } else if (!seen[g][k]) {
          problems.add("ids " + id_name(static_cast<uint32_t>(g), k) + " are in no brick");
        } else if (std::memcmp(&stored[g][k], &t, sizeof(Triangle)) != 0) {
          problems.add("ids " + id_name(static_cast<uint32_t>(g), k) +
                       " name a different triangle in the store");
        }
        ++k;
      }
      return Status::Ok();
    });
    const Status streamed = (*source)->stream(sink);
    ASSERT_TRUE(streamed.ok()) << streamed.to_string();
    EXPECT_EQ(k, m.inputs[g].triangle_count) << "input " << g;
    EXPECT_EQ(degenerate, m.inputs[g].degenerate_count) << "input " << g;
    total += k;
    degenerate_total += degenerate;
  }
  EXPECT_EQ(problems.count(), 0u) << problems.report();

  // Counts and bounds in the manifest and the summary.
  EXPECT_EQ(m.triangle_count, total);
  EXPECT_EQ(m.degenerate_count, degenerate_total);
  EXPECT_EQ(m.brick_triangles_target, brick_triangles);
  EXPECT_EQ(m.bounds, all_bricks);
  EXPECT_EQ(summary.triangles, total);
  EXPECT_EQ(summary.degenerate_triangles, degenerate_total);
  EXPECT_EQ(summary.bricks, store.brick_count());
  EXPECT_EQ(summary.max_brick_triangles, largest_brick);
  EXPECT_EQ(summary.bytes_on_disk, store.bytes_on_disk());

  // The upper hierarchy: walked from the root, every node is reached once, the
  // leaves are exactly the bricks, each once, and bounds nest.
  const auto& nodes = m.upper.nodes;
  const uint32_t n = store.brick_count();
  ASSERT_EQ(nodes.size(), 2 * static_cast<size_t>(n) - 1);
  std::vector<uint8_t> node_reached(nodes.size(), 0), brick_leaf(n, 0);
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0u, 1u}};
  uint32_t depth = 0;
  Problems tree;
  while (!stack.empty()) {
    const auto [index, level] = stack.back();
    stack.pop_back();
    if (index >= nodes.size() || node_reached[index]++) {
      tree.add("node " + std::to_string(index) + " missing or reached twice");
      continue;
    }
    depth = std::max(depth, level);
    const UpperNode& node = nodes[index];
    if (node.is_leaf) {
      if (node.child_or_brick >= n || brick_leaf[node.child_or_brick]++) {
        tree.add("leaf " + std::to_string(index) + " names a missing or repeated brick");
      } else if (!node.bounds.contains(m.bricks[node.child_or_brick].bounds)) {
        tree.add("leaf " + std::to_string(index) + " does not contain its brick");
      }
      continue;
    }
    for (uint32_t c = node.child_or_brick; c < node.child_or_brick + 2; ++c) {
      if (c >= nodes.size()) {
        tree.add("node " + std::to_string(index) + " has a child out of range");
      } else {
        if (!node.bounds.contains(nodes[c].bounds)) {
          tree.add("node " + std::to_string(index) + " does not contain child " + std::to_string(c));
        }
        stack.push_back({c, level + 1});
      }
    }
  }
  EXPECT_EQ(tree.count(), 0u) << tree.report();
  EXPECT_EQ(std::count(node_reached.begin(), node_reached.end(), 1), static_cast<long>(nodes.size()));
  EXPECT_EQ(std::count(brick_leaf.begin(), brick_leaf.end(), 1), static_cast<long>(n));
  EXPECT_EQ(nodes[0].bounds, m.bounds);
  EXPECT_EQ(summary.upper_depth, depth);
  EXPECT_EQ(m.upper.depth(), depth);
}

struct Packed {
  TempDir dir;
  std::string store;
  Expected<PackSummary> summary = internal_error("not packed");
};

// In-memory group cap for the out-of-core tests (0: derived from memory_mb).
uint64_t g_max_group_triangles = 0;

PackOptions options_for(const std::vector<std::string>& inputs, const std::string& output,
                        uint32_t brick_triangles, uint64_t memory_mb = 1024) {
  PackOptions options;
  options.max_group_triangles = g_max_group_triangles;
  options.inputs = inputs;
  options.output = output;
  options.brick_triangles = brick_triangles;
  options.memory_mb = memory_mb;
  options.sync = false;
  return options;
}

// Packs into a fresh temporary directory and checks the round trip.
void pack_and_check(const std::vector<std::string>& inputs, uint32_t brick_triangles,
                    uint64_t memory_mb = 1024, PackSummary* summary_out = nullptr) {
  SCOPED_TRACE("brick_triangles " + std::to_string(brick_triangles) + ", memory_mb " +
               std::to_string(memory_mb));
  TempDir dir;
  const std::string store = dir.file("scene");
  const auto summary = pack_scene(options_for(inputs, store, brick_triangles, memory_mb));
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  expect_round_trip(store, inputs, brick_triangles, *summary);
  if (summary_out != nullptr) *summary_out = *summary;
}

// Entries beside a store: nothing but what the test itself put there.
std::vector<std::string> directory_entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// name -> contents of every file in a store directory.
std::map<std::string, std::string> snapshot(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    files[entry.path().filename().string()] = text.str();
  }
  return files;
}

// ---- round trips --------------------------------------------------------------

class ModelRoundTrip : public ::testing::TestWithParam<std::string> {};

TEST_P(ModelRoundTrip, EveryTriangleIsInExactlyOneBrickBitIdenticalWithItsIdsAtSeveralBrickSizes) {
  const std::string path = model_path(GetParam());
  for (const uint32_t brick : {1u << 20, 1000u, 64u}) pack_and_check({path}, brick);
}

INSTANTIATE_TEST_SUITE_P(SharedModels, ModelRoundTrip,
                         ::testing::Values("stanford-bunny.obj", "beast.obj", "fandisk.obj", "homer.obj",
                                           "spot.obj", "teapot.obj", "igea.ply"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           std::string name = info.param;
                           for (char& c : name) {
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           }
                           return name;
                         });

TEST(ScenePackerRoundTrip, OneBrickPerTriangleWhenBrickTrianglesIsOne) {
  pack_and_check({"gen:sphere?level=2"}, 1);
  pack_and_check({model_path("teapot.obj")}, 1);
}

class GeneratorRoundTrip : public ::testing::TestWithParam<std::pair<const char*, const char*>> {};

TEST_P(GeneratorRoundTrip, EveryTriangleIsInExactlyOneBrickBitIdenticalWithItsIdsAtSeveralBrickSizes) {
  for (const uint32_t brick : {1u << 20, 1000u, 64u}) pack_and_check({GetParam().second}, brick);
}

INSTANTIATE_TEST_SUITE_P(Generators, GeneratorRoundTrip,
                         ::testing::Values(std::pair{"sphere", "gen:sphere?level=4"},
                                           std::pair{"terrain", "gen:terrain?n=64"},
                                           std::pair{"city", "gen:city?of=(gen:sphere?level=2)&copies=20"},
                                           std::pair{"stadium", "gen:stadium?level=4"},
                                           std::pair{"torus", "gen:torus"}),
                         [](const auto& info) { return std::string(info.param.first); });

TEST(ScenePackerRoundTrip, SingleBrickSceneHasASingleLeafUpperHierarchy) {
  TempDir dir;
  const auto summary = pack_scene(options_for({"gen:sphere?level=3"}, dir.file("s"), 1u << 20));
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  EXPECT_EQ(summary->bricks, 1u);
  EXPECT_EQ(summary->upper_depth, 1u);
  EXPECT_EQ(summary->out_of_core_levels, 0u);
  EXPECT_EQ(summary->spill_bytes_written, 0u);  // the scene fit in memory
  auto store = SceneStore::open(dir.file("s"));
  ASSERT_TRUE(store.ok());
  ASSERT_EQ((*store)->manifest().upper.nodes.size(), 1u);
  EXPECT_TRUE((*store)->manifest().upper.nodes[0].is_leaf);
  EXPECT_EQ((*store)->manifest().upper.nodes[0].child_or_brick, 0u);
}

// ---- out of core ----------------------------------------------------------------

// The smallest budget PackOptions documents, with the in-memory group capped
// at 150 k triangles so that scenes of a few MiB must go out of core.
constexpr uint64_t kSmallMemoryMb = 32;
class ScenePackerOutOfCore : public ::testing::Test {
 protected:
  void SetUp() override { g_max_group_triangles = 150'000; }
  void TearDown() override { g_max_group_triangles = 0; }
};

TEST_F(ScenePackerOutOfCore, TerrainLargerThanMemoryBudgetSpillsAndRoundTripsExactly) {
  // 1.5M triangles = 63 MiB raw, against a 32 MiB budget.
  PackSummary summary;
  pack_and_check({"gen:terrain?n=870"}, 1000, kSmallMemoryMb, &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
}

TEST_F(ScenePackerOutOfCore, CityLargerThanMemoryBudgetSpillsAndRoundTripsExactly) {
  // 1.2M triangles in 240 separate clusters.
  PackSummary summary;
  pack_and_check({"gen:city?of=(gen:sphere?level=4)&copies=240"}, 500, kSmallMemoryMb, &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
}

TEST_F(ScenePackerOutOfCore, ModelFilesLargerThanMemoryBudgetSpillToDiskAndRoundTrip) {
  // Files cannot be re-streamed cheaply, so groups go through spill files.
  PackSummary summary;
  pack_and_check({model_path("igea.ply"), model_path("stanford-bunny.obj")}, 1000, kSmallMemoryMb, &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
  EXPECT_GT(summary.spill_bytes_written, 0u);
}

std::string obj_with_repeated_triangle(size_t copies, bool with_outlier) {
  std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nv 6 5 5\nv 5 6 5\n";
  text.reserve(text.size() + copies * 8 + 16);
  for (size_t i = 0; i < copies; ++i) text += "f 1 2 3\n";
  if (with_outlier) text += "f 4 5 6\n";
  return text;
}

TEST_F(ScenePackerOutOfCore, IdenticalCentroidsBeyondMemoryBudgetAreChunkedAndRoundTrip) {
  // 400k copies of one triangle: 17 MiB, more than one in-memory group at 32 MiB,
  // and no grid can separate them.
  TempDir inputs;
  const std::string obj = inputs.file("same.obj");
  write_text_file(obj, obj_with_repeated_triangle(400'000, false));
  PackSummary summary;
  pack_and_check({obj}, 1000, kSmallMemoryMb, &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
  EXPECT_EQ(summary.triangles, 400'000u);
}

TEST_F(ScenePackerOutOfCore, IdenticalCentroidsPlusOneOutlierBeyondMemoryBudgetRoundTrip) {
  TempDir inputs;
  const std::string obj = inputs.file("same.obj");
  write_text_file(obj, obj_with_repeated_triangle(400'000, true));
  PackSummary summary;
  pack_and_check({obj}, 1000, kSmallMemoryMb, &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
  EXPECT_EQ(summary.triangles, 400'001u);
}

TEST_F(ScenePackerOutOfCore, SeveralGeneratedInputsOutOfCoreKeepTheirIdsAndRoundTrip) {
  PackSummary summary;
  pack_and_check({"gen:terrain?n=300", "gen:city?of=(gen:sphere?level=3)&copies=500"}, 700, kSmallMemoryMb,
                 &summary);
  EXPECT_GE(summary.out_of_core_levels, 1u);
  EXPECT_EQ(summary.spill_bytes_written, 0u);  // generated groups are regenerated, never spilled
}

TEST_F(ScenePackerOutOfCore, GeneratedIdenticalCentroidsBeyondTheGroupCapAreChunkedAndRoundTrip) {
  // A city of one copy of a mesh whose triangles all share a centroid: no grid
  // cell can split them, with or without an outlier that gives the grid extent.
  for (const bool outlier : {false, true}) {
    TempDir inputs;
    const std::string obj = inputs.file("same.obj");
    write_text_file(obj, obj_with_repeated_triangle(400'000, outlier));
    PackSummary summary;
    pack_and_check({"gen:city?of=" + obj + "&copies=1&spacing=1"}, 1000, kSmallMemoryMb, &summary);
    EXPECT_GE(summary.out_of_core_levels, 1u);
    EXPECT_EQ(summary.triangles, outlier ? 400'001u : 400'000u);
  }
}

// ---- determinism ------------------------------------------------------------------

// Generated inputs are generated and partitioned on all cores; the store must
// not depend on how many there are.
TEST(ScenePackerDeterminism, GeneratedStoresAreByteIdenticalOnOneThreadAndOnAllThreads) {
  struct Case {
    std::vector<std::string> inputs;
    uint32_t brick_triangles;
    uint64_t max_group_triangles;  // 0: in memory
  };
  const std::vector<Case> cases{
      {{"gen:city?of=(gen:sphere?level=3)&copies=700"}, 2000, 0},        // one group, grid subgroups
      {{"gen:city?of=(gen:sphere?level=3)&copies=700"}, 2000, 150'000},  // several groups
      {{"gen:terrain?n=200", "gen:city?of=(gen:sphere?level=2)&copies=300"}, 500, 40'000},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.inputs.front() + ", group cap " + std::to_string(c.max_group_triangles));
    TempDir dir;
    std::map<std::string, std::string> stores[2];
    for (int run = 0; run < 2; ++run) {
      std::unique_ptr<tbb::global_control> one_thread;
      if (run == 0) {
        one_thread = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, 1);
      }
      PackOptions options = options_for(c.inputs, dir.file("s" + std::to_string(run)), c.brick_triangles, 64);
      options.max_group_triangles = c.max_group_triangles;
      const auto summary = pack_scene(options);
      ASSERT_TRUE(summary.ok()) << summary.status().to_string();
      if (c.max_group_triangles > 0) {
        EXPECT_GE(summary->out_of_core_levels, 1u);
      }
      stores[run] = snapshot(dir.file("s" + std::to_string(run)));
    }
    ASSERT_EQ(stores[0].size(), 2u);
    for (const auto& [name, bytes] : stores[0]) {
      EXPECT_TRUE(stores[1][name] == bytes) << name << " differs between 1 thread and all threads";
    }
    PackSummary summary;
    g_max_group_triangles = c.max_group_triangles;
    pack_and_check(c.inputs, c.brick_triangles, 64, &summary);
    g_max_group_triangles = 0;
  }
}

// ---- ids ------------------------------------------------------------------------

TEST(ScenePackerIds, ObjPlyAndGeneratorGetGeometryIdsByPositionAndPrimitiveIdsFromZero) {
  const std::vector<std::string> inputs{model_path("spot.obj"), model_path("igea.ply"), "gen:sphere?level=2"};
  TempDir dir;
  const auto summary = pack_scene(options_for(inputs, dir.file("s"), 4096));
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  // expect_round_trip checks (g, p) for p in 0..n_g-1 each exactly once.
  expect_round_trip(dir.file("s"), inputs, 4096, *summary);
  auto store = SceneStore::open(dir.file("s"));
  ASSERT_TRUE(store.ok());
  const Manifest& m = (*store)->manifest();
  ASSERT_EQ(m.inputs.size(), 3u);
  EXPECT_EQ(m.inputs[0].triangle_count, 5856u);
  EXPECT_GT(m.inputs[1].triangle_count, 0u);
  EXPECT_EQ(m.inputs[2].triangle_count, 320u);
  // Every geometry id occurs, and nothing else.
  std::vector<uint64_t> per_geometry(3, 0);
  BrickData brick;
  for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
    ASSERT_TRUE((*store)->load_brick(b, brick).ok());
    for (const TriangleId& id : brick.ids) {
      ASSERT_LT(id.geometry_id, 3u);
      ++per_geometry[id.geometry_id];
    }
  }
  for (size_t g = 0; g < 3; ++g) EXPECT_EQ(per_geometry[g], m.inputs[g].triangle_count) << g;
}

TEST(ScenePackerIds, DegenerateTrianglesAreKeptCountedAndKeepTheirIds) {
  TempDir dir;
  const std::string obj = dir.file("degenerate.obj");
  // Triangles: 0 fine, 1 repeated vertex, 2 collinear, 3 fine, 4 all three the
  // same vertex, a quad fanned into 5 (collinear) and 6 (fine), 7 fine.
  write_text_file(obj,
                  "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 0 0 1\n"
                  "f 1 2 3\n"
                  "f 1 1 2\n"
                  "f 1 2 4\n"
                  "f 1 3 5\n"
                  "f 3 3 3\n"
                  "f 1 2 4 3\n"
                  "f 2 3 5\n");
  const auto summary = pack_scene(options_for({obj}, dir.file("s"), 2));
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  EXPECT_EQ(summary->triangles, 8u);
  EXPECT_EQ(summary->degenerate_triangles, 4u);
  auto store = SceneStore::open(dir.file("s"));
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->manifest().degenerate_count, 4u);
  EXPECT_EQ((*store)->manifest().inputs[0].degenerate_count, 4u);
  expect_round_trip(dir.file("s"), {obj}, 2, *summary);
  // The ids name the user's triangles: primitive 4 is (v3, v3, v3), the quad's
  // degenerate half 5 is (v1, v2, v4) and its other half 6 is (v1, v4, v3).
  BrickData brick;
  int found = 0;
  for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
    ASSERT_TRUE((*store)->load_brick(b, brick).ok());
    for (size_t i = 0; i < brick.ids.size(); ++i) {
      const uint32_t p = brick.ids[i].primitive_id;
      if (p == 4) {
        EXPECT_EQ(brick.triangles[i], (Triangle{{0, 1, 0}, {0, 1, 0}, {0, 1, 0}}));
      }
      if (p == 5) {
        EXPECT_EQ(brick.triangles[i], (Triangle{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}));
      }
      if (p == 6) {
        EXPECT_EQ(brick.triangles[i], (Triangle{{0, 0, 0}, {2, 0, 0}, {0, 1, 0}}));
      }
      found += p >= 4 && p <= 6;
    }
  }
  EXPECT_EQ(found, 3);
}

// ---- options --------------------------------------------------------------------

// Without a brick size: a scene of at most kSmallSceneTriangles triangles is
// one brick; a larger one is cut into bricks of at most
// kDefaultBrickTriangles, and the manifest names the target in effect.
TEST(ScenePackerOptions, DefaultBrickSizeKeepsSmallScenesWholeAndCutsLargeOnes) {
  struct Case {
    const char* input;
    uint64_t triangles;
  };
  for (const Case& c : {Case{"gen:sphere?level=6", 81920}, Case{"gen:sphere?level=7", 327680}}) {
    SCOPED_TRACE(c.input);
    TempDir dir;
    PackOptions options = options_for({c.input}, dir.file("s"), 1);
    options.brick_triangles.reset();
    const auto summary = pack_scene(options);
    ASSERT_TRUE(summary.ok()) << summary.status().to_string();
    EXPECT_EQ(summary->triangles, c.triangles);
    auto store = SceneStore::open(dir.file("s"));
    ASSERT_TRUE(store.ok()) << store.status().to_string();
    const Manifest& manifest = (*store)->manifest();
    if (c.triangles <= kSmallSceneTriangles) {
      EXPECT_EQ(summary->bricks, 1u);
      EXPECT_EQ(summary->brick_triangles_target, c.triangles);
      EXPECT_EQ(manifest.brick_triangles_target, c.triangles);
    } else {
      EXPECT_GE(summary->bricks, c.triangles / kDefaultBrickTriangles);
      EXPECT_EQ(summary->brick_triangles_target, kDefaultBrickTriangles);
      EXPECT_EQ(manifest.brick_triangles_target, kDefaultBrickTriangles);
      EXPECT_LE(summary->max_brick_triangles, kDefaultBrickTriangles);
    }
  }
}

TEST(ScenePackerOptions, RejectsZeroOversizedBrickTrianglesAndTooSmallMemoryWithoutOutput) {
  TempDir dir;
  const std::string out = dir.file("s");
  struct Case {
    uint32_t brick;
    uint64_t memory_mb;
    const char* mentions;
  };
  for (const Case& c :
       {Case{0, 1024, "--brick-tris"}, Case{kMaxBrickTriangles + 1, 1024, "--brick-tris"},
        Case{1000, kMinPackMemoryMb - 1, "--mem-mb"}, Case{kMaxBrickTriangles, 64, "--mem-mb"}}) {
    SCOPED_TRACE(c.mentions + std::string(" ") + std::to_string(c.brick) + " " + std::to_string(c.memory_mb));
    const auto summary = pack_scene(options_for({"gen:sphere?level=1"}, out, c.brick, c.memory_mb));
    ASSERT_FALSE(summary.ok());
    EXPECT_EQ(summary.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(summary.status().message().find(c.mentions), std::string::npos) << summary.status().message();
    EXPECT_TRUE(directory_entries(dir.path()).empty());
  }
}

TEST(ScenePackerOptions, RejectsNoInputsAndNoOutput) {
  TempDir dir;
  EXPECT_EQ(pack_scene(options_for({}, dir.file("s"), 100)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(pack_scene(options_for({"gen:torus"}, "", 100)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(directory_entries(dir.path()).empty());
}

// ---- atomicity ------------------------------------------------------------------

TEST(ScenePackerAtomicity, PackOntoExistingStoreWithoutOverwriteFailsAndLeavesItByteIdentical) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  const auto before = snapshot(out);
  const auto again = pack_scene(options_for({"gen:torus"}, out, 64));
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), StatusCode::kAlreadyExists);
  EXPECT_NE(again.status().message().find(out), std::string::npos);
  EXPECT_EQ(snapshot(out), before);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
}

TEST(ScenePackerAtomicity, ExistingNonStorePathIsNotReplacedWithoutOverwrite) {
  TempDir dir;
  const std::string out = dir.file("s");
  write_text_file(out, "precious");
  const auto result = pack_scene(options_for({"gen:torus"}, out, 64));
  EXPECT_EQ(result.status().code(), StatusCode::kAlreadyExists);
  std::ifstream in(out);
  std::string text;
  in >> text;
  EXPECT_EQ(text, "precious");
}

TEST(ScenePackerAtomicity, FailingPackWithBadInputAfterGoodOnesLeavesNoOutputAndNoPartialDirectory) {
  TempDir inputs;
  const std::string garbled = inputs.file("garbled.obj");
  write_text_file(garbled, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
  for (const std::string& bad : {inputs.file("missing.obj"), garbled, std::string("gen:nosuchgenerator")}) {
    SCOPED_TRACE(bad);
    TempDir dir;
    const auto result =
        pack_scene(options_for({"gen:sphere?level=2", model_path("spot.obj"), bad}, dir.file("s"), 64));
    ASSERT_FALSE(result.ok());
    EXPECT_TRUE(directory_entries(dir.path()).empty())
        << "left behind: " << directory_entries(dir.path()).front();
  }
}

TEST(ScenePackerAtomicity, OverwriteReplacesAnExistingStore) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  auto options = options_for({"gen:torus"}, out, 1000);
  options.overwrite = true;
  const auto summary = pack_scene(options);
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  expect_round_trip(out, {"gen:torus"}, 1000, *summary);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
}

// The old store is moved aside under a name with the pid; a leftover of that
// name (an interrupted run of a process that had the same pid) is kept and the
// swap still succeeds.
TEST(ScenePackerAtomicity, OverwriteSucceedsBesideALeftoverWithTheSameAsideName) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  const std::string leftover = out + ".replaced-" + std::to_string(::getpid());
  std::filesystem::create_directories(leftover + "/kept");
  auto options = options_for({"gen:torus"}, out, 1000);
  options.overwrite = true;
  const auto summary = pack_scene(options);
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  expect_round_trip(out, {"gen:torus"}, 1000, *summary);
  EXPECT_TRUE(std::filesystem::exists(leftover + "/kept"));
  EXPECT_EQ(directory_entries(dir.path()).size(), 2u);
}

TEST(ScenePackerAtomicity, FailingPackWithOverwriteLeavesTheOldStoreIntact) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  const auto before = snapshot(out);
  auto options = options_for({"gen:torus", dir.file("missing.ply")}, out, 64);
  options.overwrite = true;
  ASSERT_FALSE(pack_scene(options).ok());
  EXPECT_EQ(snapshot(out), before);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
  EXPECT_TRUE(SceneStore::open(out).ok());
}

// ---- --force replaces only an Outcore store ----------------------------------------

// Every file under dir (recursively) with its bytes.
std::map<std::string, std::string> tree_snapshot(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    files[fs::relative(entry.path(), dir).string()] = testing::read_file_bytes(entry.path().string());
  }
  return files;
}

Expected<PackSummary> force_pack(const std::vector<std::string>& inputs, const std::string& output) {
  auto options = options_for(inputs, output, 1000);
  options.overwrite = true;
  return pack_scene(options);
}

void expect_refused_naming(const Expected<PackSummary>& result, const std::string& path,
                           const std::string& why) {
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.status().message().find(path), std::string::npos) << result.status().to_string();
  EXPECT_NE(result.status().message().find(why), std::string::npos) << result.status().to_string();
}

TEST(ScenePackerForce, ADirectoryOfUserFilesIsRefusedAndKeptIntact) {
  TempDir dir;
  const std::string out = dir.file("photos");
  fs::create_directories(out + "/2026");
  write_text_file(out + "/notes.txt", "precious");
  write_text_file(out + "/2026/a.jpg", "also precious");
  const auto before = tree_snapshot(out);
  expect_refused_naming(force_pack({"gen:torus"}, out), out, "not an Outcore store");
  EXPECT_EQ(tree_snapshot(out), before);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"photos"});
}

TEST(ScenePackerForce, ARegularFileIsRefusedAndKeptIntact) {
  TempDir dir;
  const std::string out = dir.file("s");
  write_text_file(out, "precious");
  expect_refused_naming(force_pack({"gen:torus"}, out), out, "regular file");
  EXPECT_EQ(testing::read_file_bytes(out), "precious");
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
}

TEST(ScenePackerForce, TheInputItselfIsNeverReplaced) {
  TempDir dir;
  const std::string input = dir.file("tri.obj");
  const std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  write_text_file(input, text);
  expect_refused_naming(force_pack({"gen:torus", input}, input), input, "input");
  EXPECT_EQ(testing::read_file_bytes(input), text);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"tri.obj"});
}

// A store that somebody put an input into: the input would go with the store.
TEST(ScenePackerForce, AStoreHoldingAnInputIsRefusedAndKeptIntact) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  const std::string input = out + "/tri.obj";
  write_text_file(input, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const auto before = tree_snapshot(out);
  // Also through another spelling of the same path.
  for (const std::string& spelled : {input, dir.path() + "/./s/../s/tri.obj"}) {
    SCOPED_TRACE(spelled);
    expect_refused_naming(force_pack({spelled}, out), out, "lies inside it");
    EXPECT_EQ(tree_snapshot(out), before);
  }
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
}

TEST(ScenePackerForce, AStoreHoldingOtherFilesIsRefusedAndKeptIntact) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  write_text_file(out + "/notes.txt", "precious");
  const auto before = tree_snapshot(out);
  expect_refused_naming(force_pack({"gen:torus"}, out), out, "'notes.txt'");
  EXPECT_EQ(tree_snapshot(out), before);
}

TEST(ScenePackerForce, ASymbolicLinkIsRefusedAndItsTargetKept) {
  TempDir dir;
  const std::string target = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, target, 64)).ok());
  const auto before = tree_snapshot(target);
  fs::create_directory_symlink(target, dir.file("link"));
  expect_refused_naming(force_pack({"gen:torus"}, dir.file("link")), dir.file("link"), "symbolic link");
  EXPECT_EQ(tree_snapshot(target), before);
  EXPECT_TRUE(fs::is_symlink(dir.file("link")));
}

// The store a server has opened gets proxies.bin beside it; it is still a store.
TEST(ScenePackerForce, AStoreWithItsProxyFileIsReplaced) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  write_text_file(out + "/proxies.bin", "cache");
  const auto summary = force_pack({"gen:torus"}, out);
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  expect_round_trip(out, {"gen:torus"}, 1000, *summary);
  EXPECT_FALSE(fs::exists(out + "/proxies.bin"));
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
}

// ---- a city's base mesh under the memory bound -----------------------------------

// 20 * 4^9 = 5.2 M triangles: 60 MiB of index triples alone, more than half of
// 32 MiB. Refused before the base is generated (it would take seconds).
TEST(ScenePackerCityBase, ABaseWhoseTrianglesExceedHalfTheBudgetIsRefusedUpFront) {
  TempDir dir;
  const auto start = std::chrono::steady_clock::now();
  const auto result =
      pack_scene(options_for({"gen:city?of=(gen:sphere?level=9)&copies=2"}, dir.file("s"), 1000, 32));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kResourceExhausted);
  for (const char* part : {"gen:city", "gen:sphere?level=9", "60 MiB", "16 MiB", "--mem-mb 32"})
    EXPECT_NE(result.status().message().find(part), std::string::npos)
        << part << " in " << result.status().to_string();
  EXPECT_LT(seconds, 1.0);
  EXPECT_TRUE(directory_entries(dir.path()).empty());
}

// 20 * 4^8 = 1.3 M triangles: 15 MiB of triples fit in 16 MiB, the vertices and
// the welding table do not; found while reading, long before the whole base.
TEST(ScenePackerCityBase, ABaseThatOutgrowsHalfTheBudgetWhileReadIsRefused) {
  TempDir dir;
  const auto result =
      pack_scene(options_for({"gen:city?of=(gen:sphere?level=8)&copies=2"}, dir.file("s"), 1000, 32));
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kResourceExhausted);
  for (const char* part : {"gen:sphere?level=8", "more than 16 MiB", "of 1310720 triangles", "--mem-mb 32"})
    EXPECT_NE(result.status().message().find(part), std::string::npos)
        << part << " in " << result.status().to_string();
  EXPECT_TRUE(directory_entries(dir.path()).empty());
}

// A base that fits is held outside the triangle groups: the plan reserves it.
TEST(ScenePackerCityBase, ABaseThatFitsIsPackedExactly) {
  PackSummary summary;
  // Chunks of 16 K triangles cover under a third of the base's vertices, so
  // they transform their corners; expect_round_trip streams whole copies.
  pack_and_check({"gen:city?of=(gen:sphere?level=7)&copies=3"}, 2000, kSmallMemoryMb, &summary);
}

// Cancels (as SIGINT would) once the packer's temporary directory exists, so the
// cancellation lands mid-pack, after data has been written.
TEST(ScenePackerAtomicity, CancelledPackRemovesItsTemporaryDirectoryAndLeavesTheOldStore) {
  TempDir dir;
  const std::string out = dir.file("s");
  ASSERT_TRUE(pack_scene(options_for({"gen:sphere?level=2"}, out, 64)).ok());
  const auto before = snapshot(out);
  std::atomic<bool> done{false}, saw_partial{false};
  std::thread watcher([&] {
    while (!done.load()) {
      for (const std::string& name : directory_entries(dir.path())) {
        if (name.find(".partial-") != std::string::npos) {
          saw_partial = true;
          request_cancel();
          return;
        }
      }
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
  auto options = options_for({"gen:terrain?n=700"}, out, 1000, kSmallMemoryMb);
  options.overwrite = true;
  const auto result = pack_scene(options);
  done = true;
  watcher.join();
  reset_cancel();
  ASSERT_TRUE(saw_partial.load()) << "the pack finished before it could be cancelled";
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kCancelled);
  EXPECT_NE(result.status().message().find("interrupted"), std::string::npos);
  EXPECT_EQ(directory_entries(dir.path()), std::vector<std::string>{"s"});
  EXPECT_EQ(snapshot(out), before);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
