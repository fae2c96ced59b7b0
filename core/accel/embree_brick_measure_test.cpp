// Measurements behind the constants in embree_brick.{h,cpp} and the factory's
// defaults. Disabled by default (they take minutes); run with
//   build/tests/outcore_tests --gtest_also_run_disabled_tests
//       --gtest_filter='*EmbreeBrickMeasure*'
#include <gtest/gtest.h>
#include <malloc.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/embree_brick.h"
#include "core/accel/embree_device.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using namespace accel_test;

const char* quality_name(EmbreeQuality q) {
  return q == EmbreeQuality::kLow ? "low" : (q == EmbreeQuality::kMedium ? "medium" : "high");
}

std::vector<EmbreeBrickConfig> all_configs() {
  std::vector<EmbreeBrickConfig> out;
  for (bool robust : {false, true}) {
    for (EmbreeQuality q : {EmbreeQuality::kLow, EmbreeQuality::kMedium, EmbreeQuality::kHigh}) {
      out.push_back({robust, q});
    }
  }
  return out;
}

// Peak and final bytes per triangle for every shape, size and option
// combination; prints the worst ratios per configuration.
TEST(EmbreeBrickMeasure, DISABLED_MemoryTable) {
  // OUTCORE_MEASURE_THREADS=k limits TBB (Embree's builders) to k threads.
  const char* threads = std::getenv("OUTCORE_MEASURE_THREADS");
  tbb::global_control limit(
      tbb::global_control::max_allowed_parallelism,
      threads != nullptr ? std::stoul(threads) : tbb::this_task_arena::max_concurrency());
  const BrickData bunny = load_brick_from(bunny_path());
  const BrickData sphere = load_brick_from("gen:sphere?level=8");
  const BrickData random = random_triangles(1000000, 7);
  const BrickData degenerate = degenerate_heavy(1000000, 9);
  const BrickData scattered = scattered_triangles(1000000, 11);
  const std::vector<std::pair<std::string, const BrickData*>> shapes = {{"bunny", &bunny},
                                                                        {"sphere", &sphere},
                                                                        {"random", &random},
                                                                        {"scattered", &scattered},
                                                                        {"degenerate", &degenerate}};
  std::map<std::string, std::pair<double, double>> worst;  // config -> (peak/n, final/n) for n >= 1000
  std::printf("%-10s %8s %-6s %-6s %12s %12s %12s %9s %9s %8s\n", "shape", "n", "robust", "qual", "embree",
              "memory", "peak", "mem/n", "peak/n", "secs");
  for (const auto& [name, base] : shapes) {
    for (uint64_t n : {10ull, 100ull, 1000ull, 10000ull, 100000ull, 1000000ull}) {
      for (const auto& config : all_configs()) {
        auto accel = EmbreeBrickAccel::build(resized(*base, n), config);
        ASSERT_TRUE(accel.ok()) << accel.status().to_string();
        const auto& a = **accel;
        const double mem_n = double(a.memory_bytes()) / double(n);
        const double peak_n = double(a.build_peak_bytes()) / double(n);
        std::printf("%-10s %8llu %-6d %-6s %12llu %12llu %12llu %9.1f %9.1f %8.4f\n", name.c_str(),
                    (unsigned long long)n, config.robust, quality_name(config.quality),
                    (unsigned long long)a.embree_bytes(), (unsigned long long)a.memory_bytes(),
                    (unsigned long long)a.build_peak_bytes(), mem_n, peak_n, a.build_seconds());
        const std::string key =
            std::string(config.robust ? "robust " : "fast ") + quality_name(config.quality);
        auto& w = worst[key];
        if (n >= 1000) w = {std::max(w.first, peak_n), std::max(w.second, mem_n)};
        EXPECT_LE(a.memory_bytes(), EmbreeBrickAccel::reserve_bytes(n, config));
        EXPECT_LE(a.build_peak_bytes(), EmbreeBrickAccel::reserve_bytes(n, config));
      }
    }
  }
  for (const auto& [key, w] : worst)
    std::printf("worst (n>=1000) %-14s peak/n %.1f  final/n %.1f\n", key.c_str(), w.first, w.second);
}

// Heap bytes per scene that Embree allocates without reporting them to the
// memory monitor: build many tiny bricks one thread at a time and compare
// malloc's in-use bytes with what memory_bytes() accounts (minus its constant).
TEST(EmbreeBrickMeasure, DISABLED_UntrackedBytes) {
  const BrickData sphere = load_brick_from("gen:sphere?level=1");
  for (const auto& config : all_configs()) {
    std::vector<std::unique_ptr<EmbreeBrickAccel>> keep;
    // Warm up thread-local state first.
    for (int i = 0; i < 50; ++i)
      keep.push_back(std::move(EmbreeBrickAccel::build(resized(sphere, 80), config).value()));
    keep.clear();
    const auto before = mallinfo2();
    uint64_t accounted = 0;
    constexpr int kBricks = 400;
    for (int i = 0; i < kBricks; ++i) {
      keep.push_back(std::move(EmbreeBrickAccel::build(resized(sphere, 80), config).value()));
      accounted += keep.back()->memory_bytes() - EmbreeBrickAccel::kUntrackedBytes;
    }
    const auto after = mallinfo2();
    const double heap = double((after.uordblks + after.hblkhd) - (before.uordblks + before.hblkhd));
    std::printf("robust=%d quality=%s: heap %.0f B/brick, accounted %.0f B/brick, untracked %.0f B/brick\n",
                config.robust, quality_name(config.quality), heap / kBricks, double(accounted) / kBricks,
                (heap - double(accounted)) / kBricks);
  }
}

// CPU time of the calling thread: other processes on the machine do not count.
double thread_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double mrays_per_second(const EmbreeBrickAccel& accel, const std::vector<Ray>& rays,
                        const std::vector<uint32_t>& ids, int repeats) {
  std::vector<Hit> hits(rays.size());
  double best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    std::fill(hits.begin(), hits.end(), Hit{});
    const double t0 = thread_seconds();
    accel.intersect(ids, rays.data(), hits.data());
    best = std::min(best, thread_seconds() - t0);
  }
  return double(ids.size()) / best * 1e-6;
}

// The same rays through a plain rtcIntersect1 loop over a plain indexed
// scene of the same triangles: the peer our per-ray overhead is measured
// against.
RTCBuildQuality rtc_quality(EmbreeQuality q) {
  return q == EmbreeQuality::kLow
             ? RTC_BUILD_QUALITY_LOW
             : (q == EmbreeQuality::kMedium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
}

double raw_embree_mrays_per_second(const BrickData& brick, const EmbreeBrickConfig& config,
                                   const std::vector<Ray>& rays, int repeats) {
  auto device = EmbreeDevice::instance();
  std::vector<float> vertices;
  for (const Triangle& t : brick.triangles) {
    for (const Vec3f& v : {t.v0, t.v1, t.v2}) vertices.insert(vertices.end(), {v.x, v.y, v.z});
  }
  vertices.push_back(0);
  std::vector<uint32_t> indices(vertices.size() / 3 + 1);
  for (uint32_t i = 0; i < indices.size(); ++i) indices[i] = i;
  RTCScene scene = rtcNewScene((*device)->handle());
  rtcSetSceneFlags(scene, config.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(scene, rtc_quality(config.quality));
  RTCGeometry geometry = rtcNewGeometry((*device)->handle(), RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geometry, rtc_quality(config.quality));
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices.data(), 0, 12,
                             3 * brick.triangles.size());
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices.data(), 0, 12,
                             brick.triangles.size());
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);
  std::vector<RTCRayHit> rayhits(rays.size());
  double best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    for (std::size_t i = 0; i < rays.size(); ++i) {
      const Ray& ray = rays[i];
      rayhits[i].ray = {ray.origin.x,
                        ray.origin.y,
                        ray.origin.z,
                        ray.tnear,
                        ray.direction.x,
                        ray.direction.y,
                        ray.direction.z,
                        0.0f,
                        ray.tfar,
                        0xffffffffu,
                        0,
                        0};
      rayhits[i].hit.geomID = RTC_INVALID_GEOMETRY_ID;
    }
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    const double t0 = thread_seconds();
    for (RTCRayHit& rh : rayhits) rtcIntersect1(scene, &context, &rh);
    best = std::min(best, thread_seconds() - t0);
  }
  rtcReleaseScene(scene);
  return double(rays.size()) / best * 1e-6;
}

// Single-thread closest-hit speed on the bunny with 1M incoherent rays, per
// option combination, and build time; with the plain-loop peer of each.
TEST(EmbreeBrickMeasure, DISABLED_TraceSpeed) {
  const BrickData bunny = load_brick_from(bunny_path());
  const auto rays = rays_from_outside(bounds_of(bunny), 1000000, 3);
  const auto ids = all_ids(rays.size());
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  for (const auto& config : all_configs()) {
    double build = 1e30;
    std::unique_ptr<EmbreeBrickAccel> accel;
    for (int i = 0; i < 3; ++i) {
      BrickData copy = bunny;
      accel = std::move(EmbreeBrickAccel::build(std::move(copy), config).value());
      build = std::min(build, accel->build_seconds());
    }
    double ours = 0, raw = 0;  // best of 4, alternating, to see through other load on the machine
    for (int r = 0; r < 4; ++r) {
      ours = std::max(ours, mrays_per_second(*accel, rays, ids, 1));
      raw = std::max(raw, raw_embree_mrays_per_second(bunny, config, rays, 1));
    }
    std::printf(
        "robust=%d quality=%-6s build %.3f s (1 thread)  intersect %.2f M rays/s, plain loop %.2f, ratio "
        "%.2f\n",
        config.robust, quality_name(config.quality), build, ours, raw, ours / raw);
  }
}

// Morton code of a point in [0,1)^3, 10 bits per axis.
uint32_t morton3(float x, float y, float z) {
  const auto spread = [](uint32_t v) {
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
  };
  const auto q = [](float f) { return static_cast<uint32_t>(std::clamp(f, 0.0f, 0.999f) * 1024.0f); };
  return (spread(q(x)) << 2) | (spread(q(y)) << 1) | spread(q(z));
}

// Rays sorted the way an engine might queue them: by direction octant, then
// by the Morton code of the origin within the scene bounds, then direction.
std::vector<Ray> sorted_for_coherence(std::vector<Ray> rays, const Aabb& b) {
  const Vec3f lo = b.lo, ext = b.extent();
  std::vector<std::pair<uint64_t, uint32_t>> keys(rays.size());
  for (uint32_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    const uint64_t octant = (r.direction.x < 0) | ((r.direction.y < 0) << 1) | ((r.direction.z < 0) << 2);
    const Vec3f o = r.origin, d = normalize(r.direction);
    const float span = 3.0f;  // origins lie within 1.5 half-diagonals of the centre
    const uint32_t mo = morton3((o.x - lo.x) / (span * ext.x) + 0.33f, (o.y - lo.y) / (span * ext.y) + 0.33f,
                                (o.z - lo.z) / (span * ext.z) + 0.33f);
    const uint32_t md = morton3(d.x * 0.5f + 0.5f, d.y * 0.5f + 0.5f, d.z * 0.5f + 0.5f) >> 18;
    keys[i] = {(octant << 42) | (uint64_t{mo} << 12) | md, i};
  }
  std::sort(keys.begin(), keys.end());
  std::vector<Ray> out(rays.size());
  for (std::size_t i = 0; i < keys.size(); ++i) out[i] = rays[keys[i].second];
  return out;
}

// A pinhole camera looking at the bunny, rays in 4x4 tiles: the most coherent case.
std::vector<Ray> camera_rays(const Aabb& b, int width, int height) {
  const Vec3f c = b.center();
  const Vec3f e = b.extent();
  const Vec3f eye = c + Vec3f(0, 0, 2.5f * e.z + 1.5f * e.x);
  std::vector<Ray> rays;
  for (int ty = 0; ty < height; ty += 4) {
    for (int tx = 0; tx < width; tx += 4) {
      for (int y = ty; y < ty + 4; ++y) {
        for (int x = tx; x < tx + 4; ++x) {
          const Vec3f target =
              c + Vec3f((x / float(width) - 0.5f) * 1.2f * e.x, (y / float(height) - 0.5f) * 1.2f * e.y, 0);
          Ray r;
          r.origin = eye;
          r.direction = target - eye;
          rays.push_back(r);
        }
      }
    }
  }
  return rays;
}

// The same scene traced with Embree's packet and stream entry points, for the
// record (the accel uses rtcIntersect1): 1 = rtcIntersect1 loop, 16 =
// rtcIntersect16 on consecutive rays, M = rtcIntersect1M with the coherent flag.
double packet_mrays_per_second(RTCScene scene, const std::vector<Ray>& rays, int mode) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  if (mode == 2) context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  if (mode == 3) mode = 2;  // rtcIntersect1M, incoherent flag
  uint64_t hits = 0;
  const double t0 = thread_seconds();
  if (mode == 0) {
    RTCRayHit rh;
    for (const Ray& ray : rays) {
      rh.ray = {ray.origin.x,
                ray.origin.y,
                ray.origin.z,
                ray.tnear,
                ray.direction.x,
                ray.direction.y,
                ray.direction.z,
                0.0f,
                ray.tfar,
                0xffffffffu,
                0,
                0};
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &context, &rh);
      hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
  } else if (mode == 1) {
    alignas(64) RTCRayHit16 p;
    alignas(64) int valid[16];
    for (std::size_t b = 0; b < rays.size(); b += 16) {
      for (int l = 0; l < 16; ++l) {
        const std::size_t i = b + l;
        valid[l] = i < rays.size() ? -1 : 0;
        const Ray& ray = rays[std::min(i, rays.size() - 1)];
        p.ray.org_x[l] = ray.origin.x;
        p.ray.org_y[l] = ray.origin.y;
        p.ray.org_z[l] = ray.origin.z;
        p.ray.dir_x[l] = ray.direction.x;
        p.ray.dir_y[l] = ray.direction.y;
        p.ray.dir_z[l] = ray.direction.z;
        p.ray.tnear[l] = ray.tnear;
        p.ray.tfar[l] = ray.tfar;
        p.ray.time[l] = 0;
        p.ray.mask[l] = 0xffffffffu;
        p.ray.id[l] = 0;
        p.ray.flags[l] = 0;
        p.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
      }
      rtcIntersect16(valid, scene, &context, &p);
      for (int l = 0; l < 16; ++l) hits += valid[l] && p.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID;
    }
  } else {
    constexpr std::size_t kChunk = 256;
    std::vector<RTCRayHit> chunk(kChunk);
    for (std::size_t b = 0; b < rays.size(); b += kChunk) {
      const std::size_t n = std::min(kChunk, rays.size() - b);
      for (std::size_t l = 0; l < n; ++l) {
        const Ray& ray = rays[b + l];
        chunk[l].ray = {ray.origin.x,
                        ray.origin.y,
                        ray.origin.z,
                        ray.tnear,
                        ray.direction.x,
                        ray.direction.y,
                        ray.direction.z,
                        0.0f,
                        ray.tfar,
                        0xffffffffu,
                        0,
                        0};
        chunk[l].hit.geomID = RTC_INVALID_GEOMETRY_ID;
      }
      rtcIntersect1M(scene, &context, chunk.data(), static_cast<unsigned>(n), sizeof(RTCRayHit));
      for (std::size_t l = 0; l < n; ++l) hits += chunk[l].hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
  }
  const double s = thread_seconds() - t0;
  EXPECT_GT(hits, 0u);
  return double(rays.size()) / s * 1e-6;
}

TEST(EmbreeBrickMeasure, DISABLED_PacketSpeed) {
  const BrickData bunny = load_brick_from(bunny_path());
  const Aabb b = bounds_of(bunny);
  const auto random = rays_from_outside(b, 1000000, 3);
  const auto sorted = sorted_for_coherence(random, b);
  const auto camera = camera_rays(b, 1024, 1024);
  const auto camera256 = camera_rays(b, 256, 256);
  const auto camera128 = camera_rays(b, 128, 128);
  const auto camera64 = camera_rays(b, 64, 64);
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  EmbreeBrickConfig config;
  config.quality = EmbreeQuality::kMedium;
  auto accel = EmbreeBrickAccel::build(BrickData(bunny), config);
  ASSERT_TRUE(accel.ok());
  auto device = EmbreeDevice::instance();
  std::vector<float> vertices;
  for (const Triangle& t : bunny.triangles) {
    for (const Vec3f& v : {t.v0, t.v1, t.v2}) vertices.insert(vertices.end(), {v.x, v.y, v.z});
  }
  vertices.push_back(0);
  std::vector<uint32_t> indices(vertices.size() / 3 + 1);
  for (uint32_t i = 0; i < indices.size(); ++i) indices[i] = i;
  RTCScene scene = rtcNewScene((*device)->handle());
  RTCGeometry geometry = rtcNewGeometry((*device)->handle(), RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices.data(), 0, 12,
                             3 * bunny.triangles.size());
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices.data(), 0, 12,
                             bunny.triangles.size());
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);
  for (const auto& [name, rays] :
       {std::pair{"random", &random}, std::pair{"sorted", &sorted}, std::pair{"camera", &camera},
        std::pair{"cam256", &camera256}, std::pair{"cam128", &camera128}, std::pair{"cam64", &camera64}}) {
    double best[5] = {0, 0, 0, 0, 0};
    for (int r = 0; r < 3; ++r) {
      for (int mode = 0; mode < 4; ++mode) {
        best[mode] = std::max(best[mode], packet_mrays_per_second(scene, *rays, mode == 3 ? 3 : mode));
      }
      best[4] = std::max(best[4], mrays_per_second(**accel, *rays, all_ids(rays->size()), 1));
    }
    std::printf(
        "%-7s rtcIntersect1 %.2f  rtcIntersect16 %.2f  rtcIntersect1M coherent %.2f incoherent %.2f  accel "
        "%.2f M rays/s\n",
        name, best[0], best[1], best[2], best[3], best[4]);
  }
  rtcReleaseScene(scene);
}

// For profiling (perf record): the accel alone on 1M random bunny rays (or,
// with OUTCORE_MEASURE_CAMERA=1, 1024^2 camera rays), 5 times.
TEST(EmbreeBrickMeasure, DISABLED_AccelOnly) {
  const BrickData bunny = accel_test::load_brick_from(accel_test::bunny_path());
  const auto rays = std::getenv("OUTCORE_MEASURE_CAMERA")
                        ? camera_rays(accel_test::bounds_of(bunny), 1024, 1024)
                        : accel_test::rays_from_outside(accel_test::bounds_of(bunny), 1000000, 3);
  EmbreeBrickConfig config;
  config.quality = EmbreeQuality::kMedium;
  auto accel = EmbreeBrickAccel::build(BrickData(bunny), config);
  ASSERT_TRUE(accel.ok());
  for (int r = 0; r < 5; ++r) {
    std::printf("%.2f M rays/s\n", mrays_per_second(**accel, rays, accel_test::all_ids(rays.size()), 1));
  }
}

// Default choice: trace speed of the candidate configurations on the bunny,
// 1M incoherent rays, single thread, alternating 8 times (best of each).
TEST(EmbreeBrickMeasure, DISABLED_DefaultChoice) {
  const BrickData bunny = accel_test::load_brick_from(accel_test::bunny_path());
  const auto rays = accel_test::rays_from_outside(accel_test::bounds_of(bunny), 1000000, 3);
  const auto ids = accel_test::all_ids(rays.size());
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  const std::vector<EmbreeBrickConfig> configs = {
      {false, EmbreeQuality::kLow}, {false, EmbreeQuality::kMedium}, {false, EmbreeQuality::kHigh},
      {true, EmbreeQuality::kLow},  {true, EmbreeQuality::kMedium},  {true, EmbreeQuality::kHigh}};
  std::vector<std::unique_ptr<EmbreeBrickAccel>> accels;
  std::vector<double> best(configs.size(), 0.0), build(configs.size(), 1e30);
  for (int r = 0; r < 8; ++r) {
    for (std::size_t c = 0; c < configs.size(); ++c) {
      auto accel = std::move(EmbreeBrickAccel::build(BrickData(bunny), configs[c]).value());
      build[c] = std::min(build[c], accel->build_seconds());
      best[c] = std::max(best[c], mrays_per_second(*accel, rays, ids, 1));
    }
  }
  for (std::size_t c = 0; c < configs.size(); ++c) {
    std::printf("robust=%d quality=%-6s build %.3f s, intersect %.2f M rays/s, build + 1M rays %.3f s\n",
                configs[c].robust, quality_name(configs[c].quality), build[c], best[c],
                build[c] + 1.0 / best[c]);
  }
}
}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
