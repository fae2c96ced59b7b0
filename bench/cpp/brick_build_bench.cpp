// How fast a brick is built: each structure the factory makes by name
// (default: the bvh, binned SAH then the 8-wide collapse and the triangle
// packets, against the Embree brick, rtcCommitScene with the engine's default
// Embree settings) on the same triangles, same run, one thread each
// (tbb::global_control), the median of --runs builds, interleaved build by
// build so that a noisy moment hits every structure. A brick is built once
// per cold batch and once per reload under a tight budget, so this is what a
// first answer and an out-of-core batch pay per triangle.
// Meshes: the bunny and the Igea scan from tests/data/models, whole and cut to
// brick sizes (their first 4,096 and 20,480 triangles), and a generated sphere.
// Usage: outcore_brick_build_bench [--runs 9] [--models DIR]
//                                  [--structures bvh,embree,grid,...]
// Prints one table (times and each structure's time over the first one's);
// writes nothing.
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/source/source_factory.h"
#include "core/store/brick_data.h"

namespace outcore {
namespace {

using Clock = std::chrono::steady_clock;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Every triangle of `spec` (a file or a gen: spec) as one brick; exits with
// the reason when it cannot be read.
BrickData load(const std::string& spec) {
  BrickData brick;
  auto triangles = read_all_triangles(spec);
  if (!triangles.ok()) {
    std::fprintf(stderr, "outcore_brick_build_bench: %s\n", triangles.status().to_string().c_str());
    std::exit(1);
  }
  brick.triangles = std::move(*triangles);
  for (uint32_t k = 0; k < brick.triangles.size(); ++k) brick.ids.push_back({0, k});
  return brick;
}

BrickData first(const BrickData& whole, std::size_t n) {
  BrickData part;
  n = std::min(n, whole.triangles.size());
  part.triangles.assign(whole.triangles.begin(), whole.triangles.begin() + n);
  part.ids.assign(whole.ids.begin(), whole.ids.begin() + n);
  return part;
}

std::vector<std::string> split_names(const std::string& list) {
  std::vector<std::string> names;
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t comma = std::min(list.find(',', start), list.size());
    if (comma > start) names.push_back(list.substr(start, comma - start));
    start = comma + 1;
  }
  return names;
}

// Median seconds of `runs` builds of copies of `brick` by each builder,
// interleaved; a failed build ends the bench.
std::vector<double> time_builds(const BrickData& brick, int runs,
                                const std::vector<std::unique_ptr<BrickBuilder>>& builders) {
  std::vector<std::vector<double>> seconds(builders.size());
  for (int r = 0; r < runs; ++r) {
    for (std::size_t b = 0; b < builders.size(); ++b) {
      BrickData copy = brick;
      const auto start = Clock::now();
      const auto accel = builders[b]->build(std::move(copy));
      seconds[b].push_back(std::chrono::duration<double>(Clock::now() - start).count());
      if (!accel.ok()) {
        std::fprintf(stderr, "outcore_brick_build_bench: %s build failed: %s\n", builders[b]->name().c_str(),
                     accel.status().to_string().c_str());
        std::exit(1);
      }
    }
  }
  std::vector<double> medians;
  for (auto& s : seconds) medians.push_back(median(s));
  return medians;
}

int run(int argc, char** argv) {
  int runs = 9;
  std::string models = OUTCORE_MODELS_DIR;
  std::string structures = "bvh,embree";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
      runs = std::max(1, std::atoi(argv[++i]));
    } else if (std::strcmp(argv[i], "--models") == 0 && i + 1 < argc) {
      models = argv[++i];
    } else if (std::strcmp(argv[i], "--structures") == 0 && i + 1 < argc) {
      structures = argv[++i];
    } else {
      std::fprintf(
          stderr,
          "usage: outcore_brick_build_bench [--runs 9] [--models DIR] [--structures bvh,embree,...]\n");
      return 2;
    }
  }
  std::vector<std::unique_ptr<BrickBuilder>> builders;
  for (const std::string& name : split_names(structures)) {
    auto builder = make_brick_builder(name, {});
    if (!builder.ok()) {
      std::fprintf(stderr, "outcore_brick_build_bench: %s\n", builder.status().to_string().c_str());
      return 2;
    }
    builders.push_back(std::move(*builder));
  }
  if (builders.empty()) {
    std::fprintf(stderr, "outcore_brick_build_bench: --structures names none\n");
    return 2;
  }
  const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  const BrickData bunny = load(models + "/stanford-bunny.obj");
  const BrickData igea = load(models + "/igea.ply");
  struct Mesh {
    std::string name;
    BrickData brick;
  };
  const std::vector<Mesh> meshes = {
      {"bunny, first 4,096", first(bunny, 4096)},
      {"bunny, first 20,480", first(bunny, 20480)},
      {"bunny", bunny},
      {"igea, first 20,480", first(igea, 20480)},
      {"igea", igea},
      {"gen:sphere?level=7", load("gen:sphere?level=7")},
  };
  const std::string& base = builders.front()->name();
  std::printf("| mesh | triangles |");
  for (const auto& b : builders) std::printf(" %s ms |", b->name().c_str());
  for (std::size_t b = 1; b < builders.size(); ++b) {
    std::printf(" %s / %s time |", builders[b]->name().c_str(), base.c_str());
  }
  std::printf(" %s M triangles/s |\n|---|---|", base.c_str());
  for (std::size_t b = 0; b < 2 * builders.size(); ++b) std::printf("---|");
  std::printf("\n");
  for (const Mesh& mesh : meshes) {
    const std::vector<double> seconds = time_builds(mesh.brick, runs, builders);
    const double n = static_cast<double>(mesh.brick.triangles.size());
    std::printf("| %s | %.0f |", mesh.name.c_str(), n);
    for (const double t : seconds) std::printf(" %.2f |", t * 1e3);
    for (std::size_t b = 1; b < seconds.size(); ++b) std::printf(" %.2fx |", seconds[b] / seconds[0]);
    std::printf(" %.2f |\n", n / seconds[0] / 1e6);
  }
  return 0;
}

}  // namespace
}  // namespace outcore

int main(int argc, char** argv) {
  return outcore::run(argc, argv);
}
