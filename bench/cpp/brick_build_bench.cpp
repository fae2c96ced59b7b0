// How fast a brick is built: the bvh brick structure (binned SAH, then the
// 8-wide collapse and the triangle packets) against the Embree brick
// (rtcCommitScene, the engine's default Embree settings) on the same
// triangles, same run, one thread each (tbb::global_control), the median of
// --runs builds. A brick is built once per cold batch and once per reload
// under a tight budget, so this is what a first answer and an out-of-core
// batch pay per triangle.
// Meshes: the bunny and the Igea scan from tests/data/models, whole and cut to
// brick sizes (their first 4,096 and 20,480 triangles), and a generated sphere.
// Usage: outcore_brick_build_bench [--runs 9] [--models DIR]
// Prints one table; writes nothing.
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/accel/bvh/bvh_brick.h"
#include "core/accel/embree_brick.h"
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

// Median seconds of `runs` builds of copies of `brick` by `build`, which
// returns whether the build succeeded (a failure ends the bench).
template <class Build>
double time_builds(const BrickData& brick, int runs, Build&& build) {
  std::vector<double> seconds;
  for (int r = 0; r < runs; ++r) {
    BrickData copy = brick;
    const auto start = Clock::now();
    const bool ok = build(std::move(copy));
    seconds.push_back(std::chrono::duration<double>(Clock::now() - start).count());
    if (!ok) {
      std::fprintf(stderr, "outcore_brick_build_bench: a build failed\n");
      std::exit(1);
    }
  }
  return median(seconds);
}

int run(int argc, char** argv) {
  int runs = 9;
  std::string models = OUTCORE_MODELS_DIR;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
      runs = std::max(1, std::atoi(argv[++i]));
    } else if (std::strcmp(argv[i], "--models") == 0 && i + 1 < argc) {
      models = argv[++i];
    } else {
      std::fprintf(stderr, "usage: outcore_brick_build_bench [--runs 9] [--models DIR]\n");
      return 2;
    }
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
  std::printf("| mesh | triangles | bvh ms | Embree ms | bvh / Embree time | bvh M triangles/s |\n");
  std::printf("|---|---|---|---|---|---|\n");
  for (const Mesh& mesh : meshes) {
    const double bvh = time_builds(mesh.brick, runs, [](BrickData&& b) {
      return BvhBrickAccel::build(std::move(b), BvhBrickConfig{}).ok();
    });
    const double embree = time_builds(mesh.brick, runs, [](BrickData&& b) {
      return EmbreeBrickAccel::build(std::move(b), EmbreeBrickConfig{}).ok();
    });
    const double n = static_cast<double>(mesh.brick.triangles.size());
    std::printf("| %s | %.0f | %.2f | %.2f | %.2fx | %.2f |\n", mesh.name.c_str(), n, bvh * 1e3, embree * 1e3,
                bvh / embree, n / bvh / 1e6);
  }
  return 0;
}

}  // namespace
}  // namespace outcore

int main(int argc, char** argv) {
  return outcore::run(argc, argv);
}
