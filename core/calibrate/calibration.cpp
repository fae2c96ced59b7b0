#include "core/calibrate/calibration.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <random>

#include "core/accel/auto/auto_brick.h"
#include "core/gen/generator_factory.h"

namespace outcore {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// The builds and traces are repeated until they have run this many times
// or for min_seconds in all; the fastest repetition counts.
constexpr int kMaxRepetitions = 25;

// Incoherent rays through the brick's box: from a sphere around it (1.5x its
// half diagonal) to uniform points inside it, as bench/make_rays.py does for
// whole scenes.
std::vector<Ray> rays_through(const std::vector<Triangle>& triangles, uint32_t count, uint64_t seed) {
  Aabb box;
  for (const Triangle& t : triangles) box.extend(t.bounds());
  const Vec3d lo(box.lo), hi(box.hi);
  const Vec3d center = (lo + hi) * 0.5;
  const Vec3d e = hi - lo;
  const double radius = std::max(1e-6, 0.75 * std::sqrt(e.x * e.x + e.y * e.y + e.z * e.z));
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Ray> rays(count);
  for (Ray& ray : rays) {
    Vec3d d(normal(rng), normal(rng), normal(rng));
    const double length = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    d = length > 0 ? d * (1.0 / length) : Vec3d(0, 0, 1);
    const Vec3d origin = center + d * radius;
    const Vec3d target(lo.x + unit(rng) * e.x, lo.y + unit(rng) * e.y, lo.z + unit(rng) * e.z);
    ray.origin = Vec3f(origin);
    ray.direction = Vec3f(target - origin);
    if (ray.direction == Vec3f(0, 0, 0)) ray.direction = Vec3f(0, 0, 1);
  }
  return rays;
}

Expected<StructureMeasure> measure(const BrickBuilder& builder, const BrickData& data,
                                   const std::vector<Ray>& rays, double min_seconds) {
  StructureMeasure result;
  result.build_seconds = std::numeric_limits<double>::infinity();
  std::unique_ptr<BrickAccel> accel;
  double spent = 0;
  for (int rep = 0; rep < kMaxRepetitions && (rep == 0 || spent < min_seconds); ++rep) {
    BrickData copy = data;
    const auto t0 = Clock::now();
    OUTCORE_ASSIGN_OR_RETURN(accel, builder.build(std::move(copy)));
    const double seconds = seconds_between(t0, Clock::now());
    result.build_seconds = std::min(result.build_seconds, seconds);
    spent += seconds;
  }
  std::vector<uint32_t> ids(rays.size());
  std::iota(ids.begin(), ids.end(), 0u);
  std::vector<Hit> hits(rays.size());
  double best = std::numeric_limits<double>::infinity();
  spent = 0;
  for (int rep = 0; rep < kMaxRepetitions && (rep == 0 || spent < min_seconds); ++rep) {
    std::fill(hits.begin(), hits.end(), Hit{});
    const auto t0 = Clock::now();
    accel->intersect(ids, rays.data(), hits.data());
    const double seconds = seconds_between(t0, Clock::now());
    best = std::min(best, seconds);
    spent += seconds;
  }
  result.trace_seconds_per_ray = best / static_cast<double>(std::max<std::size_t>(1, rays.size()));
  return result;
}

// Solves (A + ridge) w = b for a small symmetric system by Gaussian
// elimination with partial pivoting.
std::array<double, kFeatureCount> solve(std::array<std::array<double, kFeatureCount>, kFeatureCount> a,
                                        std::array<double, kFeatureCount> b) {
  constexpr std::size_t n = kFeatureCount;
  for (std::size_t col = 0; col < n; ++col) {
    std::size_t pivot = col;
    for (std::size_t r = col + 1; r < n; ++r) {
      if (std::abs(a[r][col]) > std::abs(a[pivot][col])) pivot = r;
    }
    std::swap(a[col], a[pivot]);
    std::swap(b[col], b[pivot]);
    if (std::abs(a[col][col]) < 1e-300) continue;
    for (std::size_t r = col + 1; r < n; ++r) {
      const double f = a[r][col] / a[col][col];
      for (std::size_t k = col; k < n; ++k) a[r][k] -= f * a[col][k];
      b[r] -= f * b[col];
    }
  }
  std::array<double, n> w{};
  for (std::size_t i = n; i-- > 0;) {
    double sum = b[i];
    for (std::size_t k = i + 1; k < n; ++k) sum -= a[i][k] * w[k];
    w[i] = std::abs(a[i][i]) < 1e-300 ? 0.0 : sum / a[i][i];
  }
  return w;
}

// Ridge weight on the non-constant coefficients (the regressors are of
// order 1 to 20; this keeps unvaried features at ~0 without biasing the rest).
constexpr double kRidge = 0.05;

std::array<double, kFeatureCount> fit_log_linear(const std::vector<std::array<double, kFeatureCount>>& x,
                                                 const std::vector<double>& y) {
  std::array<std::array<double, kFeatureCount>, kFeatureCount> a{};
  std::array<double, kFeatureCount> b{};
  for (std::size_t s = 0; s < x.size(); ++s) {
    for (std::size_t i = 0; i < kFeatureCount; ++i) {
      for (std::size_t j = 0; j < kFeatureCount; ++j) a[i][j] += x[s][i] * x[s][j];
      b[i] += x[s][i] * y[s];
    }
  }
  for (std::size_t i = 1; i < kFeatureCount; ++i) a[i][i] += kRidge * static_cast<double>(x.size());
  return solve(a, b);
}

Expected<SampleBrick> generated_sample(const std::string& spec) {
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<Generator> generator, make_typed_generator(spec));
  SampleBrick sample;
  sample.label = spec;
  sample.data.triangles.reserve(generator->triangle_count());
  CallbackSink sink([&](std::span<const Triangle> batch) {
    sample.data.triangles.insert(sample.data.triangles.end(), batch.begin(), batch.end());
    return Status::Ok();
  });
  OUTCORE_RETURN_IF_ERROR(generator->stream(sink));
  sample.data.ids.resize(sample.data.triangles.size());
  for (uint32_t i = 0; i < sample.data.ids.size(); ++i) sample.data.ids[i] = TriangleId{0, i};
  return sample;
}

}  // namespace

const std::vector<std::string>& builtin_sample_specs() {
  static const std::vector<std::string> specs = {
      "gen:sphere?level=1",
      "gen:sphere?level=3",
      "gen:sphere?level=5",
      "gen:sphere?level=7",
      "gen:torus",
      "gen:terrain?n=30&size=10&height=1",
      "gen:terrain?n=200&size=100&height=3",
      "gen:stadium?level=3",
      "gen:stadium?level=6",
      "gen:city?of=(gen:sphere?level=1)&copies=50&spacing=4",
      "gen:city?of=(gen:sphere?level=3)&copies=40&spacing=3",
      "gen:city?of=(gen:terrain?n=24&size=2&height=0.1)&copies=60&spacing=3&tilt=30",
  };
  return specs;
}

Expected<std::vector<SampleBrick>> builtin_sample_bricks() {
  std::vector<SampleBrick> samples;
  for (const std::string& spec : builtin_sample_specs()) {
    OUTCORE_ASSIGN_OR_RETURN(SampleBrick sample, generated_sample(spec));
    samples.push_back(std::move(sample));
  }
  return samples;
}

Expected<std::vector<SampleBrick>> sample_store_bricks(const SceneStore& store, uint32_t max_bricks) {
  std::vector<uint32_t> order(store.brick_count());
  std::iota(order.begin(), order.end(), 0u);
  const auto& bricks = store.manifest().bricks;
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return bricks[a].triangle_count < bricks[b].triangle_count;
  });
  std::vector<uint32_t> chosen;
  const std::size_t want = std::min<std::size_t>(max_bricks, order.size());
  for (std::size_t k = 0; k < want; ++k) {
    const std::size_t rank = want == 1 ? order.size() / 2 : k * (order.size() - 1) / (want - 1);
    if (chosen.empty() || chosen.back() != order[rank]) chosen.push_back(order[rank]);
  }
  std::vector<SampleBrick> samples;
  for (const uint32_t id : chosen) {
    SampleBrick sample;
    sample.label = "brick " + std::to_string(id);
    OUTCORE_RETURN_IF_ERROR(store.load_brick(id, sample.data));
    if (sample.data.triangles.empty()) continue;
    samples.push_back(std::move(sample));
  }
  return samples;
}

CostProfile fit_cost_profile(const std::vector<std::string>& structures,
                             const std::vector<CalibrationSample>& samples) {
  CostProfile profile;
  profile.origin = "calibration";
  std::vector<std::array<double, kFeatureCount>> x;
  for (const CalibrationSample& sample : samples) {
    x.push_back(sample.features.regressors());
    profile.samples.push_back(sample.features);
  }
  for (std::size_t s = 0; s < structures.size(); ++s) {
    std::vector<double> log_build, log_trace;
    for (const CalibrationSample& sample : samples) {
      const double per_triangle =
          sample.measures[s].build_seconds / std::max<double>(1.0, sample.features.triangles);
      log_build.push_back(std::log(std::max(per_triangle, 1e-12)));
      log_trace.push_back(std::log(std::max(sample.measures[s].trace_seconds_per_ray, 1e-12)));
    }
    StructureCost cost;
    cost.structure = structures[s];
    cost.build = fit_log_linear(x, log_build);
    cost.trace = fit_log_linear(x, log_trace);
    profile.structures.push_back(cost);
  }
  return profile;
}

Expected<Calibration> calibrate(std::vector<SampleBrick> samples, const CalibrationOptions& options) {
  Calibration calibration;
  calibration.structures = options.structures;
  if (calibration.structures.empty())
    calibration.structures.assign(std::begin(kDefaultAutoCandidates), std::end(kDefaultAutoCandidates));
  std::vector<std::unique_ptr<BrickBuilder>> builders;
  for (const std::string& name : calibration.structures) {
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<BrickBuilder> builder,
                             make_brick_builder(name, options.structure_options));
    builders.push_back(std::move(builder));
  }
  if (samples.empty()) return invalid_argument("calibration needs at least one sample brick with triangles");
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const SampleBrick& sample = samples[k];
    CalibrationSample measured;
    measured.label = sample.label;
    measured.features = measure_brick_features(sample.data.triangles);
    const std::vector<Ray> rays =
        rays_through(sample.data.triangles, options.rays_per_brick, options.seed + k);
    for (std::size_t s = 0; s < builders.size(); ++s) {
      Expected<StructureMeasure> m =
          measure(*builders[s], sample.data, rays, options.min_seconds_per_measure);
      if (!m.ok()) {
        return m.status().with_context("calibrating '" + calibration.structures[s] + "' on " + sample.label);
      }
      measured.measures.push_back(*m);
      if (options.on_measured) options.on_measured();
    }
    calibration.samples.push_back(std::move(measured));
  }
  calibration.profile = fit_cost_profile(calibration.structures, calibration.samples);
  return calibration;
}

}  // namespace outcore
