#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/cli/commands.h"
#include "core/cli/subtree_options.h"
#include "core/io/npy.h"
#include "core/query/query_engine.h"
#include "core/ray/spawn_origin.h"
#include "core/util/atomic_file.h"

namespace outcore {

namespace {

// Beyond any machine's cores; TBB would cap it anyway, but a typo (an extra
// digit, a negative number) should be an error, not a silent default.
constexpr int kMaxThreadsOption = 65536;

struct TraceArgs {
  std::string scene;
  std::string rays_path;
  std::string output_path;
  bool any_hit = false;
  uint64_t cache_mb = 1024;
  std::string policy = "lru";
  std::string brick_accel = "embree";
  SubtreeCliOptions subtree;
  std::vector<std::string> accel_options;
  std::string triangle_test;  // shorthand for --accel-opt triangle_test=NAME (bvh only)
  bool reference = false;     // float64 ground truth: brick structure "reference"
  bool no_reorder = false;
  bool no_trace_ahead = false;
  bool no_in_cache_sweep = false;
  bool no_brick_set = false;
  bool no_avx_upper = false;
  bool no_proxies = false;
  std::optional<int64_t> proxy_res;  // unset: the default resolution
  int threads = 0;
  bool print_stats = false;
  std::string stats_json_path;
  bool strict = false;
  int repeat = 1;
  std::string trace_out;
  std::string spawn_out;
  std::string spawn_side = "front";
};

Expected<BrickAccelOptions> parse_accel_options(const std::vector<std::string>& items) {
  BrickAccelOptions options;
  for (const std::string& item : items) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      return invalid_argument("--accel-opt '" + item + "' is not of the form key=value");
    }
    if (!options.emplace(item.substr(0, eq), item.substr(eq + 1)).second) {
      return invalid_argument("--accel-opt '" + item.substr(0, eq) + "' given twice");
    }
  }
  return options;
}

int run_trace(const TraceArgs& args) {
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0) {
    threads =
        std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, args.threads);
  }
  auto accel_options = parse_accel_options(args.accel_options);
  if (!accel_options.ok()) return report_command_error("trace", accel_options.status().message());
  if (args.cache_mb == 0 || args.cache_mb > (std::numeric_limits<uint64_t>::max() >> 20)) {
    return report_command_error("trace", "--cache-mb must be between 1 and " +
                                             std::to_string(std::numeric_limits<uint64_t>::max() >> 20) +
                                             ", got " + std::to_string(args.cache_mb));
  }
  EngineOptions engine_options;
  if (args.no_proxies && args.proxy_res) {
    return report_command_error("trace", "--proxy-res has no effect with --no-proxies; give one of them");
  }
  engine_options.proxies = !args.no_proxies;
  if (args.proxy_res) {
    if (*args.proxy_res < kMinProxyResolution || *args.proxy_res > kMaxProxyResolution) {
      return report_command_error(
          "trace", "--proxy-res must be between " + std::to_string(kMinProxyResolution) + " and " +
                       std::to_string(kMaxProxyResolution) + ", got " + std::to_string(*args.proxy_res));
    }
    engine_options.proxy_config.resolution = static_cast<uint32_t>(*args.proxy_res);
  }
  engine_options.cache_bytes = args.cache_mb << 20;
  engine_options.eviction_policy = args.policy;
  engine_options.brick_accel = args.brick_accel;
  const Status subtree = apply_subtree_options(args.subtree, engine_options);
  if (!subtree.ok()) return report_command_error("trace", subtree.message());
  engine_options.accel_options = *accel_options;
  if (!args.triangle_test.empty()) {
    if (args.brick_accel != "bvh") {
      return report_command_error("trace",
                                  "--triangle-test needs --brick-accel bvh (got '" + args.brick_accel + "')");
    }
    if (!engine_options.accel_options.emplace("triangle_test", args.triangle_test).second) {
      return report_command_error("trace", "--triangle-test and --accel-opt triangle_test=... both given");
    }
  }
  if (args.reference) {
    if (args.brick_accel != "embree" || !args.accel_options.empty() || !args.triangle_test.empty()) {
      return report_command_error("trace",
                                  "--reference chooses the brick structure itself: drop --brick-accel, "
                                  "--accel-opt and --triangle-test");
    }
    engine_options.brick_accel = "reference";
  }
  if (!args.spawn_out.empty() && args.any_hit) {
    return report_command_error("trace", "--spawn-out needs closest hits: drop --any-hit");
  }
  if (!args.trace_out.empty()) {
    auto trace = AccessTraceWriter::create(args.trace_out,
                                           "outcore trace " + args.scene + " --rays " + args.rays_path);
    if (!trace.ok()) return report_command_error("trace", trace.status().message());
    engine_options.access_trace = std::move(trace).value();
  }
  auto engine = QueryEngine::open(args.scene, engine_options);
  if (!engine.ok()) return report_command_error("trace", engine.status().message());
  auto rays = read_rays_npy(args.rays_path);
  if (!rays.ok()) return report_command_error("trace", rays.status().message());
  if (args.print_stats) {
    std::printf("brick structure: %s (%s)%s\n", engine_options.brick_accel.c_str(),
                describe_accel_options((*engine)->accel_options()).c_str(),
                (*engine)->cache_fits_scene() ? "" : "; the budget cannot hold the scene: trace-ahead on");
    if (const ProxySet* proxies = (*engine)->proxies()) {
      const ProxyOpenReport& report = (*engine)->proxy_report();
      std::printf("proxies: resolution %u, %u bricks, %.2f MiB, %s in %.3f s\n", proxies->config().resolution,
                  proxies->brick_count(), proxies->memory_bytes() / 1048576.0,
                  report.loaded    ? "loaded from proxies.bin"
                  : report.written ? "built and written to proxies.bin"
                                   : "built (kept in memory)",
                  report.seconds);
    }
  }

  QueryOptions query_options;
  query_options.reorder = !args.no_reorder;
  query_options.trace_ahead = !args.no_trace_ahead;
  query_options.in_cache_sweep = !args.no_in_cache_sweep;
  query_options.brick_set = !args.no_brick_set;
  query_options.avx_upper = !args.no_avx_upper;
  query_options.strict = args.strict;
  // Repeats run the same batch again on the now warm cache (the first run is
  // the cold one: time to first hit); the output is the last run's.
  std::vector<QueryStats> runs;
  std::vector<uint8_t> occluded(args.any_hit ? rays->size() : 0);
  std::vector<Hit> hits(args.any_hit ? 0 : rays->size());
  for (int r = 0; r < args.repeat; ++r) {
    QueryStats stats;
    const Status status = args.any_hit ? (*engine)->occluded(*rays, occluded, query_options, &stats)
                                       : (*engine)->intersect(*rays, hits, query_options, &stats);
    if (!status.ok()) return report_command_error("trace", status.message());
    if (args.print_stats) {
      if (args.repeat > 1)
        std::printf("run %d/%d (%s cache)\n", r + 1, args.repeat, r == 0 ? "cold" : "warm");
      std::fputs(stats.to_text().c_str(), stdout);
    }
    runs.push_back(stats);
  }
  if (engine_options.access_trace) {
    engine->reset();  // hands the cache's last buffered records to the writer
    const Status closed = engine_options.access_trace->close();
    if (!closed.ok()) return report_command_error("trace", closed.message());
  }
  const Status written =
      args.any_hit ? write_bools_npy(args.output_path, occluded) : write_hits_npy(args.output_path, hits);
  if (!written.ok()) return report_command_error("trace", written.message());
  if (!args.spawn_out.empty()) {
    const SpawnSide side = args.spawn_side == "back" ? SpawnSide::kBack : SpawnSide::kFront;
    std::vector<Vec3f> origins(hits.size());
    for (std::size_t i = 0; i < hits.size(); ++i) origins[i] = spawn_origin((*rays)[i], hits[i], side);
    const Status spawned = write_points_npy(args.spawn_out, origins);
    if (!spawned.ok()) return report_command_error("trace", spawned.message());
  }
  if (!args.stats_json_path.empty()) {
    std::string json;
    if (runs.size() == 1) {
      json = runs[0].to_json() + "\n";
    } else {
      json = "[";
      for (size_t r = 0; r < runs.size(); ++r) json += (r ? "," : "") + runs[r].to_json();
      json += "]\n";
    }
    const std::string_view parts[] = {json};
    const Status saved = write_file_atomically(args.stats_json_path, parts);
    if (!saved.ok()) return report_command_error("trace", saved.message());
  }
  return 0;
}

}  // namespace

void add_trace_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<TraceArgs>();
  CLI::App* cmd = app.add_subcommand("trace", "Trace a rays .npy against a scene store, in process");
  cmd->add_option("scene", args->scene, "Scene store directory")->required();
  cmd->add_option("--rays", args->rays_path, "Rays .npy: float32 (N,6) or (N,8)")->required();
  cmd->add_option("-o,--output", args->output_path, "Hits .npy to write (bool .npy with --any-hit)")
      ->required();
  cmd->add_flag("--any-hit", args->any_hit, "Occlusion query: write whether each ray hits anything");
  // A range check here names the value as given: "-1" would otherwise wrap
  // to 2^64 - 1 before run_trace() sees it.
  cmd->add_option("--cache-mb", args->cache_mb, "Byte budget of the brick cache, MiB")
      ->check(CLI::Range(uint64_t{1}, std::numeric_limits<uint64_t>::max() >> 20))
      ->capture_default_str();
  cmd->add_option("--policy", args->policy, "Cache eviction policy")->capture_default_str();
  cmd->add_option("--brick-accel", args->brick_accel, "Brick structure")->capture_default_str();
  add_subtree_options(*cmd, args->subtree);
  cmd->add_option("--accel-opt", args->accel_options, "Brick structure option key=value (repeatable)");
  cmd->add_option("--triangle-test", args->triangle_test,
                  "Triangle test of --brick-accel bvh: mt, watertight (default) or double");
  cmd->add_flag("--reference", args->reference,
                "Ground truth: float64 brute force per brick (watertight, slow) on the same store");
  cmd->add_flag("--no-reorder", args->no_reorder, "Trace rays one by one in input order (for comparison)");
  cmd->add_flag("--no-trace-ahead", args->no_trace_ahead,
                "Under a budget smaller than the scene, do not trace rays at a brick being built before they "
                "reach it (for comparison; answers are the same)");
  cmd->add_flag("--no-in-cache-sweep", args->no_in_cache_sweep,
                "When every brick is resident, still queue the batch at bricks instead of sweeping chunks of "
                "rays through them (for comparison; answers are the same)");
  cmd->add_flag(
      "--no-brick-set", args->no_brick_set,
      "When every brick is resident, still walk the upper hierarchy and trace brick by brick instead of "
      "one Embree scene instancing all bricks (for comparison and per-brick statistics; answers are "
      "the same)");
  cmd->add_flag("--no-avx-upper", args->no_avx_upper,
                "Walk the upper hierarchy 4-wide with SSE, one ray at a time, instead of 8-wide and in 8-ray "
                "packets with AVX (for comparison; answers are the same)");
  cmd->add_flag("--no-proxies", args->no_proxies,
                "Do not skip bricks by their occupancy proxies (for comparison; answers are the same)");
  cmd->add_option("--proxy-res", args->proxy_res,
                  "Proxy voxels along each brick's longest side (default 32; proxies.bin is rebuilt "
                  "when it has another)");
  cmd->add_option("--threads", args->threads, "Worker threads (0, the default: all cores)")
      ->check(CLI::Range(0, kMaxThreadsOption));
  cmd->add_flag("--stats", args->print_stats, "Print query statistics");
  cmd->add_option("--stats-json", args->stats_json_path, "Write query statistics as JSON to this file");
  cmd->add_option("--repeat", args->repeat, "Run the batch this many times (first cold, then warm)")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  cmd->add_option("--trace-out", args->trace_out, "Record every brick request to this CSV (for cache-sim)");
  cmd->add_option("--spawn-out", args->spawn_out,
                  "Also write (N,3) float32 origins for secondary rays from each hit (NaN on a miss), "
                  "offset off the surface (docs/ACCURACY.md)");
  cmd->add_option("--spawn-side", args->spawn_side,
                  "Side of the surface for --spawn-out: front (where the ray came from) or back")
      ->check(CLI::IsMember({"front", "back"}))
      ->capture_default_str();
  cmd->add_flag("--strict", args->strict, "Invalid rays are an error naming the first one (default: misses)");
  cmd->callback([args, &exit_code] { exit_code = run_trace(*args); });
}

}  // namespace outcore
