// Issue 27's benchmark: the dynamic layer's updates and traces, each against
// its peer in the same run (medians of --runs repetitions):
//   1. a deforming mesh of ~1 M triangles (a height field waving frame to
//      frame): our refit (DynamicMesh::moved, which also copies the tree for
//      the new version) against our build of the same vertices, and Embree's
//      refit (RTC_BUILD_QUALITY_REFIT) against its build;
//   2. tracing after 100 frames of smooth motion: the refitted tree against a
//      fresh build of the last frame (same answers, speed ratio);
//   3. a scrambling motion: the rebuild trigger fires;
//   4. transforms of 10,000 instances in one update_transforms;
//   5. query throughput while updates stream in at 30 a second, against no
//      updates;
//   6. the two top levels over moving instances (8-wide BVH, B-KD tree):
//      update time, and trace after 100 frames against a rebuild.
// Usage: outcore_dynamic_bench [--runs 7] [--grid 708] [--instances 10000]
// Prints one table; writes nothing.
#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/accel/embree_device.h"
#include "core/dynamic/dynamic_scene.h"

namespace outcore {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_of(const std::function<void()>& f) {
  const auto start = Clock::now();
  f();
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct HeightField {
  std::vector<float> base;  // x, y, z per vertex
  std::vector<uint32_t> triangles;
};

HeightField height_field(int n) {
  HeightField h;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) h.base.insert(h.base.end(), {float(i) / n, float(j) / n, 0.0f});
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      h.triangles.insert(h.triangles.end(), {a, b, d, a, d, c});
    }
  }
  return h;
}

// The field at frame f: a travelling wave (smooth motion).
void wave(const HeightField& h, int frame, std::vector<float>& out) {
  out = h.base;
  for (std::size_t v = 0; v < out.size(); v += 3)
    out[v + 2] =
        0.05f * std::sin(12.0f * out[v] + 0.1f * frame) * std::cos(9.0f * out[v + 1] - 0.07f * frame);
}

std::vector<Ray> rays_down(std::size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Ray> rays(n);
  for (Ray& r : rays) {
    r.origin = {u(rng), u(rng), 1.0f};
    r.direction = {0.3f * (u(rng) - 0.5f), 0.3f * (u(rng) - 0.5f), -1.0f};
  }
  return rays;
}

void row(const char* what, const std::string& figure, const std::string& ratio, const char* target) {
  std::printf("%-58s %-34s %-28s %s\n", what, figure.c_str(), ratio.c_str(), target);
  std::fflush(stdout);
}

std::string ms(double s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2f ms", s * 1e3);
  return buf;
}
std::string times(double x) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2fx", x);
  return buf;
}

// Embree: build and refit of the same mesh (its own peer).
void embree_rows(const HeightField& h, int runs) {
  auto device = EmbreeDevice::instance();
  if (!device.ok()) {
    row("embree", device.status().to_string(), "", "");
    return;
  }
  const RTCDevice dev = (*device)->handle();
  const std::size_t nv = h.base.size() / 3, nt = h.triangles.size() / 3;
  std::vector<double> builds, refits;
  std::vector<float> moved;
  for (int r = 0; r < runs; ++r) {
    RTCScene scene = rtcNewScene(dev);
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), nv + 1));
    auto* ib = static_cast<uint32_t*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), nt));
    wave(h, 0, moved);
    std::memcpy(vb, moved.data(), moved.size() * sizeof(float));
    std::memcpy(ib, h.triangles.data(), h.triangles.size() * sizeof(uint32_t));
    rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_REFIT);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    // Per-geometry quality (refit) applies only under the scene's low quality.
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_LOW);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_DYNAMIC);
    builds.push_back(seconds_of([&] { rtcCommitScene(scene); }));
    wave(h, r + 1, moved);
    refits.push_back(seconds_of([&] {
      std::memcpy(vb, moved.data(), moved.size() * sizeof(float));
      rtcUpdateGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(geom);
      rtcCommitScene(scene);
    }));
    rtcReleaseGeometry(geom);
    rtcReleaseScene(scene);
  }
  row("Embree 3: build / refit of the same mesh", ms(median(builds)) + " / " + ms(median(refits)),
      "refit " + times(median(builds) / median(refits)) + " faster", "peer (17-41 ms/M)");
}

void mesh_rows(int grid, int runs) {
  const HeightField h = height_field(grid);
  const std::size_t triangles = h.triangles.size() / 3;
  std::printf("height field %dx%d: %zu triangles, %zu vertices\n", grid, grid, triangles, h.base.size() / 3);
  std::vector<float> vertices;
  wave(h, 0, vertices);
  auto mesh = DynamicMesh::create(vertices, h.triangles, "bench");
  if (!mesh.ok()) std::exit((std::fprintf(stderr, "%s\n", mesh.status().to_string().c_str()), 1));
  std::vector<double> builds, refits;
  std::shared_ptr<const DynamicMesh> current = *mesh;
  for (int r = 0; r < runs; ++r) {
    wave(h, r + 1, vertices);
    builds.push_back(seconds_of([&] { (void)DynamicMesh::create(vertices, h.triangles, "bench"); }));
    refits.push_back(seconds_of([&] { current = *current->moved(vertices, "bench"); }));
  }
  row("ours: build / refit (new version: tree copied, then refit)",
      ms(median(builds)) + " / " + ms(median(refits)),
      "refit " + times(median(builds) / median(refits)) + " faster", ">= 10x; refit <= 40 ms");
  embree_rows(h, runs);

  // 100 frames of smooth motion, then trace against a fresh build.
  for (int frame = 1; frame <= 100; ++frame) {
    wave(h, frame, vertices);
    current = *current->moved(vertices, "bench");
  }
  const bool rebuilt_during = current->built_sah_cost() != (*mesh)->built_sah_cost();
  const auto fresh = current->rebuilt_fresh();
  DynamicSnapshot refitted, rebuilt;
  for (auto* s : {&refitted, &rebuilt}) {
    s->meshes = {s == &refitted ? current : fresh};
    DynamicInstance instance;
    instance.world_box = s->meshes[0]->bounds();
    s->instances = {instance};
    build_dynamic_top_level(*s);
  }
  const std::vector<Ray> rays = rays_down(1'000'000, 5);
  std::vector<Hit> a(rays.size()), b(rays.size());
  std::vector<double> ta, tb;
  for (int r = 0; r < runs; ++r) {
    std::fill(a.begin(), a.end(), Hit{});
    std::fill(b.begin(), b.end(), Hit{});
    ta.push_back(seconds_of([&] { refitted.intersect(rays, a); }));
    tb.push_back(seconds_of([&] { rebuilt.intersect(rays, b); }));
  }
  const bool same = std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0;
  row("trace 1 M rays after 100 frames: refitted / fresh build",
      ms(median(ta)) + " / " + ms(median(tb)) + (same ? " (same hits)" : " (HITS DIFFER)"),
      "speed " + times(median(tb) / median(ta)) + " of rebuilt", ">= 0.9x");
  char sah[128];
  std::snprintf(sah, sizeof sah, "SAH %.2f (built %.2f)%s", current->sah_cost(), current->built_sah_cost(),
                rebuilt_during ? ", rebuilt on the way" : "");
  row("  its surface-area cost after 100 frames", sah, times(current->sah_cost() / current->built_sah_cost()),
      "rebuild above 1.5x");

  // A scrambling motion: vertices swapped at random.
  std::vector<float> scrambled = vertices;
  std::mt19937 rng(3);
  const std::size_t nv = scrambled.size() / 3;
  for (std::size_t v = 0; v < nv; ++v) {
    const std::size_t w = rng() % nv;
    for (int k = 0; k < 3; ++k) std::swap(scrambled[3 * v + k], scrambled[3 * w + k]);
  }
  std::shared_ptr<const DynamicMesh> after;
  const double t = seconds_of([&] { after = *current->moved(scrambled, "bench"); });
  row("scrambling motion: the update", ms(t), after->rebuilt() ? "rebuild trigger fired" : "NOT REBUILT",
      "trigger fires");
}

// The two top levels over the same moving instances: update time, and trace
// time after 100 frames of motion against a rebuild of the last frame.
void top_level_rows(int count, int runs) {
  const HeightField small = height_field(16);
  const int side = static_cast<int>(std::ceil(std::sqrt(count)));
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> step(-0.3, 0.3);
  std::vector<double> start(12 * count);
  for (int k = 0; k < count; ++k) {
    const double rows[12] = {1, 0, 0, 2.0 * (k % side), 0, 1, 0, 2.0 * (k / side), 0, 0, 1, 0};
    std::memcpy(&start[12 * k], rows, sizeof rows);
  }
  std::vector<std::vector<double>> frames(100, start);
  for (int f = 1; f < 100; ++f) {
    frames[f] = frames[f - 1];
    for (int k = 0; k < count; ++k) {
      frames[f][12 * k + 3] += step(rng);
      frames[f][12 * k + 7] += step(rng);
      frames[f][12 * k + 11] += 0.1 * step(rng);
    }
  }
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Ray> rays(1'000'000);
  for (Ray& r : rays) {
    r.origin = {u(rng) * 2 * side, u(rng) * 2 * side, 5.0f};
    r.direction = {0.4f * (u(rng) - 0.5f), 0.4f * (u(rng) - 0.5f), -1.0f};
  }
  std::vector<Hit> reference;
  for (const DynamicTopLevel kind : {DynamicTopLevel::kBvh, DynamicTopLevel::kBkd}) {
    const char* name = kind == DynamicTopLevel::kBvh ? "8-wide BVH" : "B-KD tree";
    DynamicScene scene(0, kind);
    const uint32_t mesh = scene.add_mesh(small.base, small.triangles)->id;
    std::vector<uint32_t> ids;
    for (int k = 0; k < count; ++k)
      ids.push_back(scene.add_instance(mesh, std::span(&start[12 * k], 12))->id);
    std::vector<double> updates;
    for (int f = 1; f < 100; ++f)
      updates.push_back(seconds_of([&] { (void)scene.update_transforms(ids, frames[f]); }));
    const auto refitted = scene.latest();
    DynamicSnapshot fresh = *refitted;
    const double build = seconds_of([&] { build_dynamic_top_level(fresh); });
    std::vector<Hit> a(rays.size()), b(rays.size());
    std::vector<double> ta, tb;
    for (int r = 0; r < runs; ++r) {
      std::fill(a.begin(), a.end(), Hit{});
      std::fill(b.begin(), b.end(), Hit{});
      ta.push_back(seconds_of([&] { refitted->intersect(rays, a); }));
      tb.push_back(seconds_of([&] { fresh.intersect(rays, b); }));
    }
    const bool same =
        std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)) == 0 &&
        (reference.empty() || std::memcmp(a.data(), reference.data(), a.size() * sizeof(Hit)) == 0);
    if (reference.empty()) reference = a;
    const auto c = scene.counters();
    row((std::string(name) + ": update (99 frames) / build of the top level").c_str(),
        ms(median(updates)) + " / " + ms(build) + " (" + std::to_string(c.top_rebuilds - count) +
            " rebuilds)",
        "", "");
    row((std::string(name) + ": trace after 100 frames, refitted / rebuilt").c_str(),
        ms(median(ta)) + " / " + ms(median(tb)) + (same ? " (same hits)" : " (HITS DIFFER)"),
        "speed " + times(median(tb) / median(ta)) + " of rebuilt", ">= 0.9x");
  }
}

void instance_rows(int count, int runs) {
  DynamicScene scene;
  const HeightField small = height_field(16);  // 512 triangles
  const uint32_t mesh = scene.add_mesh(small.base, small.triangles)->id;
  std::vector<uint32_t> ids;
  const int side = static_cast<int>(std::ceil(std::sqrt(count)));
  const auto place = [&](int k, int frame, double* out) {
    const double a = 0.01 * frame + 0.001 * k;
    const double rows[12] = {std::cos(a), -std::sin(a),
                             0,           2.0 * (k % side) + 0.01 * frame,
                             std::sin(a), std::cos(a),
                             0,           2.0 * (k / side),
                             0,           0,
                             1,           0};
    std::memcpy(out, rows, sizeof rows);
  };
  std::vector<double> transforms(12 * count);
  for (int k = 0; k < count; ++k) {
    place(k, 0, &transforms[12 * k]);
    ids.push_back(scene.add_instance(mesh, std::span(&transforms[12 * k], 12))->id);
  }
  std::vector<double> updates;
  for (int r = 0; r < runs; ++r) {
    for (int k = 0; k < count; ++k) place(k, r + 1, &transforms[12 * k]);
    updates.push_back(seconds_of([&] { (void)scene.update_transforms(ids, transforms); }));
  }
  row((std::to_string(count) + " instances: update_transforms (all of them)").c_str(), ms(median(updates)),
      "", "<= 5 ms");

  // Throughput with updates streaming at 30 a second against without.
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Ray> rays(1'000'000);
  for (Ray& r : rays) {
    r.origin = {u(rng) * 2 * side, u(rng) * 2 * side, 5.0f};
    r.direction = {0.2f * (u(rng) - 0.5f), 0.2f * (u(rng) - 0.5f), -1.0f};
  }
  std::vector<Hit> hits(rays.size());
  const auto trace_batches = [&](int batches) {
    std::vector<double> t;
    for (int b = 0; b < batches; ++b) {
      std::fill(hits.begin(), hits.end(), Hit{});
      t.push_back(seconds_of([&] { scene.latest()->intersect(rays, hits); }));
    }
    return median(t);
  };
  const double quiet = trace_batches(runs);
  std::atomic<bool> stop{false};
  std::atomic<int> frames{0};
  std::thread updater([&] {
    auto next = Clock::now();
    for (int frame = 100; !stop; ++frame) {
      for (int k = 0; k < count; ++k) place(k, frame, &transforms[12 * k]);
      (void)scene.update_transforms(ids, transforms);
      ++frames;
      next += std::chrono::microseconds(33'333);
      std::this_thread::sleep_until(next);
    }
  });
  const double busy = trace_batches(runs);
  stop = true;
  updater.join();
  row("1 M rays over the instances: with 30 updates/s / without",
      ms(busy) + " / " + ms(quiet) + " (" + std::to_string(frames.load()) + " updates)",
      "throughput " + times(quiet / busy), ">= 0.9x");
}

}  // namespace
}  // namespace outcore

int main(int argc, char** argv) {
  int runs = 7, grid = 708, instances = 10000;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    const int value = std::atoi(argv[i + 1]);
    if (value <= 0) return std::fprintf(stderr, "%s needs a positive number\n", flag.c_str()), 2;
    if (flag == "--runs")
      runs = value;
    else if (flag == "--grid")
      grid = value;
    else if (flag == "--instances")
      instances = value;
    else
      return std::fprintf(stderr, "unknown option %s (--runs, --grid, --instances)\n", flag.c_str()), 2;
  }
  std::printf("%-58s %-34s %-28s %s\n", "what", "figure (median)", "ratio (same run)", "target");
  outcore::mesh_rows(grid, runs);
  outcore::instance_rows(instances, runs);
  outcore::top_level_rows(instances, runs);
  return 0;
}
