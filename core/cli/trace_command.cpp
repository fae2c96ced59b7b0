#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "core/cli/commands.h"
#include "core/cli/engine_options_cli.h"
#include "core/dynamic/dynamic_scene_file.h"
#include "core/io/npy.h"
#include "core/query/query_engine.h"
#include "core/ray/spawn_origin.h"
#include "core/util/atomic_file.h"
#include "core/util/progress.h"

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
  EngineCliOptions engine;
  bool no_reorder = false;
  bool no_trace_ahead = false;
  bool no_in_cache_sweep = false;
  bool no_brick_set = false;
  bool no_avx_upper = false;
  int threads = 0;
  bool print_stats = false;
  std::string stats_json_path;
  bool strict = false;
  int repeat = 1;
  std::string trace_out;
  std::string spawn_out;
  std::string spawn_side = "front";
  std::string dynamic_path;
  bool quiet = false;
};

// The dynamic layer from --dynamic: the file, and its instances' geometry ids.
struct DynamicFrames {
  DynamicSceneFile file;
  std::vector<uint32_t> ids;
  std::string path;
};

// The engine's options from the command line, the access trace included.
Status make_engine_options(const TraceArgs& args, EngineOptions& engine_options) {
  OUTCORE_RETURN_IF_ERROR(apply_engine_options(args.engine, engine_options));
  if (!args.spawn_out.empty() && args.any_hit) {
    return invalid_argument("--spawn-out needs closest hits: drop --any-hit");
  }
  if (!args.trace_out.empty()) {
    auto trace = AccessTraceWriter::create(args.trace_out,
                                           "outcore trace " + args.scene + " --rays " + args.rays_path);
    if (!trace.ok()) return trace.status();
    engine_options.access_trace = std::move(trace).value();
  }
  return Status::Ok();
}

void print_engine(const QueryEngine& engine, const EngineOptions& engine_options) {
  std::printf("brick structure: %s (%s)%s\n", engine_options.brick_accel.c_str(),
              describe_accel_options(engine.accel_options()).c_str(),
              engine.cache_fits_scene() ? "" : "; the budget cannot hold the scene: trace-ahead on");
  if (const ProxySet* proxies = engine.proxies()) {
    const ProxyOpenReport& report = engine.proxy_report();
    std::printf("proxies: resolution %u, %u bricks, %.2f MiB, %s in %.3f s\n", proxies->config().resolution,
                proxies->brick_count(), proxies->memory_bytes() / 1048576.0,
                report.loaded    ? "loaded from proxies.bin"
                : report.written ? "built and written to proxies.bin"
                                 : "built (kept in memory)",
                report.seconds);
  }
}

QueryOptions query_options_of(const TraceArgs& args) {
  QueryOptions query_options;
  query_options.reorder = !args.no_reorder;
  query_options.trace_ahead = !args.no_trace_ahead;
  query_options.in_cache_sweep = !args.no_in_cache_sweep;
  query_options.brick_set = !args.no_brick_set;
  query_options.avx_upper = !args.no_avx_upper;
  query_options.strict = args.strict;
  return query_options;
}

// The batch's answers: hits, or occlusion bytes with --any-hit.
struct TraceAnswers {
  std::vector<Hit> hits;
  std::vector<uint8_t> occluded;
};

// Repeats run the same batch again on the now warm cache (the first run is
// the cold one: time to first hit); the answers are the last run's.
// With --dynamic, batch r sees frame r % F of the file's transforms.
Status run_batches(const TraceArgs& args, QueryEngine& engine, std::span<const Ray> rays,
                   const DynamicFrames* dynamic, TraceAnswers& answers, std::vector<QueryStats>& runs) {
  const QueryOptions query_options = query_options_of(args);
  answers.occluded.resize(args.any_hit ? rays.size() : 0);
  answers.hits.resize(args.any_hit ? 0 : rays.size());
  // One engine call answers a whole run: rays done move run by run, while
  // the ticker keeps time and the bricks built so far current.
  ProgressStyle style;
  style.show_after = kShowProgressAfter;
  style.detail = [&engine] { return std::to_string(engine.cache().counters().builds) + " bricks built"; };
  ProgressBar progress("trace", rays.size() * static_cast<uint64_t>(args.repeat), "rays", !args.quiet, stderr,
                       std::move(style));
  ProgressTicker ticker(progress);
  for (int r = 0; r < args.repeat; ++r) {
    if (dynamic != nullptr && r > 0 && dynamic->file.frames > 1) {
      const uint32_t frame = static_cast<uint32_t>(r) % dynamic->file.frames;
      const auto moved =
          engine.dynamic().update_transforms(dynamic->ids, dynamic->file.frame_transforms(frame));
      if (!moved.ok()) return moved.status().with_context(dynamic->path + ", frame " + std::to_string(frame));
    }
    QueryStats stats;
    OUTCORE_RETURN_IF_ERROR(args.any_hit ? engine.occluded(rays, answers.occluded, query_options, &stats)
                                         : engine.intersect(rays, answers.hits, query_options, &stats));
    if (args.print_stats) {
      if (args.repeat > 1)
        std::printf("run %d/%d (%s cache)\n", r + 1, args.repeat, r == 0 ? "cold" : "warm");
      std::fputs(stats.to_text().c_str(), stdout);
    }
    runs.push_back(stats);
    progress.advance(rays.size());
  }
  progress.finish();
  return Status::Ok();
}

// -o, --spawn-out and --stats-json.
Status write_outputs(const TraceArgs& args, std::span<const Ray> rays, const TraceAnswers& answers,
                     const std::vector<QueryStats>& runs) {
  OUTCORE_RETURN_IF_ERROR(args.any_hit ? write_bools_npy(args.output_path, answers.occluded)
                                       : write_hits_npy(args.output_path, answers.hits));
  if (!args.spawn_out.empty()) {
    const SpawnSide side = args.spawn_side == "back" ? SpawnSide::kBack : SpawnSide::kFront;
    std::vector<Vec3f> origins(answers.hits.size());
    for (std::size_t i = 0; i < answers.hits.size(); ++i)
      origins[i] = spawn_origin(rays[i], answers.hits[i], side);
    OUTCORE_RETURN_IF_ERROR(write_points_npy(args.spawn_out, origins));
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
    OUTCORE_RETURN_IF_ERROR(write_file_atomically(args.stats_json_path, parts));
  }
  return Status::Ok();
}

int run_trace(const TraceArgs& args) {
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0) {
    threads =
        std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, args.threads);
  }
  EngineOptions engine_options;
  const Status options = make_engine_options(args, engine_options);
  if (!options.ok()) return report_command_error("trace", options.message());
  auto engine = QueryEngine::open(args.scene, engine_options);
  if (!engine.ok()) return report_command_error("trace", engine.status().message());
  auto rays = read_rays_npy(args.rays_path);
  if (!rays.ok()) return report_command_error("trace", rays.status().message());
  if (args.print_stats) print_engine(**engine, engine_options);

  std::unique_ptr<DynamicFrames> dynamic;
  if (!args.dynamic_path.empty()) {
    dynamic = std::make_unique<DynamicFrames>();
    dynamic->path = args.dynamic_path;
    auto file = read_dynamic_scene_file(args.dynamic_path);
    if (!file.ok()) return report_command_error("trace", file.status().message());
    dynamic->file = std::move(file).value();
    auto ids = add_dynamic_scene(dynamic->file, args.dynamic_path, (*engine)->dynamic());
    if (!ids.ok()) return report_command_error("trace", ids.status().message());
    dynamic->ids = std::move(ids).value();
  }

  TraceAnswers answers;
  std::vector<QueryStats> runs;
  const Status traced = run_batches(args, **engine, *rays, dynamic.get(), answers, runs);
  if (!traced.ok()) return report_command_error("trace", traced.message());
  if (engine_options.access_trace) {
    engine->reset();  // hands the cache's last buffered records to the writer
    const Status closed = engine_options.access_trace->close();
    if (!closed.ok()) return report_command_error("trace", closed.message());
  }
  const Status written = write_outputs(args, *rays, answers, runs);
  if (!written.ok()) return report_command_error("trace", written.message());
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
  add_cache_options(*cmd, args->engine);
  cmd->add_option("--accel-opt", args->engine.accel_options, "Brick structure option key=value (repeatable)");
  cmd->add_option("--triangle-test", args->engine.triangle_test,
                  "Triangle test of --brick-accel bvh, kdtree, bsp, grid, hgrid, octree, quadtree or auto: "
                  "mt, watertight (default) or double");
  cmd->add_flag("--reference", args->engine.reference,
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
  cmd->add_flag("--no-proxies", args->engine.no_proxies,
                "Do not skip bricks by their occupancy proxies (for comparison; answers are the same)");
  cmd->add_option("--proxy-res", args->engine.proxy_res,
                  "Proxy voxels along each brick's longest side (default 32; proxies.bin is rebuilt "
                  "when it has another)");
  cmd->add_option("--threads", args->threads, "Worker threads (0, the default: all cores)")
      ->check(CLI::Range(0, kMaxThreadsOption));
  cmd->add_flag("--stats", args->print_stats, "Print query statistics");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress line on stderr (shown for runs over 2 s)");
  cmd->add_option("--stats-json", args->stats_json_path, "Write query statistics as JSON to this file");
  cmd->add_option("--dynamic", args->dynamic_path,
                  "Dynamic geometry beside the store: meshes and per-frame instance transforms in a .npz "
                  "(meshN_vertices, meshN_triangles, instance_mesh, transforms (K,3,4) or (F,K,3,4); "
                  "batch r sees frame r % F)")
      ->check(CLI::ExistingFile);
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
