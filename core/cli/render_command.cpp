#include "core/cli/render_command.h"

#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/cli/commands.h"
#include "core/cli/engine_options_cli.h"
#include "core/cli/render_options.h"
#include "core/query/query_engine.h"
#include "core/render/pinhole_camera.h"
#include "core/util/png_writer.h"

namespace outcore {

namespace {

constexpr int kMaxThreadsOption = 65536;  // as trace's --threads

struct RenderArgs {
  std::string store;
  std::string server;
  std::string eye;
  std::string center;
  std::string up;
  double fov_deg = 0;
  std::string size;
  std::string output_path;
  std::string mode = "depth";
  bool quiet = false;
  EngineCliOptions engine;
  int threads = 0;
  double deadline_seconds = 0;
  bool no_shared_memory = false;
  std::string tls_ca;
  std::string tls_cert;
  std::string tls_key;
  std::string auth_token_file;
};

// The options that belong to one of the two ways to trace: given with the
// other, they would be silently ignored.
struct OptionGroups {
  CLI::App* engine = nullptr;  // in process, with STORE
  CLI::App* server = nullptr;  // with --server
};

Status check_trace_source(const RenderArgs& args, const OptionGroups& groups) {
  if (args.store.empty() == args.server.empty()) {
    return invalid_argument(args.store.empty() ? "give a scene STORE, or --server HOST:PORT"
                                               : "give a scene STORE or --server HOST:PORT, not both");
  }
  const bool remote = !args.server.empty();
  for (const CLI::Option* option : (remote ? groups.engine : groups.server)->get_options()) {
    if (option->count() == 0) continue;
    return invalid_argument(remote ? option->get_name() +
                                         " configures the in-process engine; the server at --server " +
                                         args.server + " has its own (give it to `outcore serve`)"
                                   : option->get_name() + " applies with --server only");
  }
  // NaN compares false both ways: it would pass a plain `< 0` test as "no deadline".
  if (!std::isfinite(args.deadline_seconds) || args.deadline_seconds < 0) {
    char given[32];
    std::snprintf(given, sizeof(given), "%g", args.deadline_seconds);
    return invalid_argument(std::string("--deadline-s must be a number >= 0 (0: none), got ") + given);
  }
  return Status::Ok();
}

Expected<PinholeRays> camera_of(const RenderArgs& args) {
  PinholeCamera camera;
  OUTCORE_ASSIGN_OR_RETURN(camera.eye, parse_vec3_option("--eye", args.eye));
  OUTCORE_ASSIGN_OR_RETURN(camera.center, parse_vec3_option("--center", args.center));
  OUTCORE_ASSIGN_OR_RETURN(camera.up, parse_vec3_option("--up", args.up));
  OUTCORE_ASSIGN_OR_RETURN(const ImageSize size, parse_size_option(args.size));
  camera.width = size.width;
  camera.height = size.height;
  camera.fov_deg = args.fov_deg;
  // Checked as the user gave it (errors name their --up). --up is the
  // world's up (an upright picture); Open3D's camera runs its rows along
  // its `up`, so the rays are asked with the world's down.
  OUTCORE_RETURN_IF_ERROR(PinholeRays::make(camera).status());
  camera.up = -camera.up;
  return PinholeRays::make(camera);
}

// Before any tracing: a render can take minutes, and the file is only
// written at the end.
Status check_output(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path parent = fs::path(path).parent_path();
  std::error_code error;
  if (!parent.empty() && !fs::is_directory(parent, error)) {
    return invalid_argument("-o " + path + ": " + parent.string() + " is not a directory");
  }
  if (fs::is_directory(path, error)) return invalid_argument("-o " + path + " is a directory");
  return Status::Ok();
}

// The engine on STORE, kept alive by the returned tracer.
Expected<TraceRays> open_engine(const RenderArgs& args) {
  EngineOptions engine_options;
  OUTCORE_RETURN_IF_ERROR(apply_engine_options(args.engine, engine_options));
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<QueryEngine> opened,
                           QueryEngine::open(args.store, engine_options));
  std::shared_ptr<QueryEngine> engine = std::move(opened);
  return TraceRays([engine](std::span<const Ray> rays, std::span<Hit> hits) {
    return engine->intersect(rays, hits, QueryOptions{});
  });
}

void print_progress(uint64_t done, uint64_t total) {
  std::fprintf(stderr, "outcore render: %llu of %llu rays traced\n", static_cast<unsigned long long>(done),
               static_cast<unsigned long long>(total));
}

int run_render(const RenderArgs& args, const OptionGroups& groups, const ConnectRenderServer& connect) {
  const auto started = std::chrono::steady_clock::now();
  Status checked = check_trace_source(args, groups);
  auto camera = camera_of(args);
  if (checked.ok() && !camera.ok()) checked = camera.status();
  auto mode = render_mode_from_name(args.mode);
  if (checked.ok() && !mode.ok()) checked = mode.status();
  if (checked.ok()) checked = check_output(args.output_path);
  if (!checked.ok()) return report_command_error("render", checked.message());

  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0) {
    threads =
        std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, args.threads);
  }
  Expected<TraceRays> trace = args.server.empty()
                                  ? open_engine(args)
                                  : connect(RemoteRenderOptions{.server = args.server,
                                                                .deadline_seconds = args.deadline_seconds,
                                                                .shared_memory = !args.no_shared_memory,
                                                                .tls_ca = args.tls_ca,
                                                                .tls_cert = args.tls_cert,
                                                                .tls_key = args.tls_key,
                                                                .auth_token_file = args.auth_token_file});
  if (!trace.ok()) return report_command_error("render", trace.status().message());

  RenderReport report;
  const bool banded = camera->pixel_count() > kDefaultBandRays;
  auto rgb = render_bands(*camera, *mode, *trace, &report, kDefaultBandRays,
                          banded && !args.quiet ? BandProgress(print_progress) : BandProgress());
  if (!rgb.ok()) return report_command_error("render", rgb.status().message());
  const Status written = write_png(args.output_path, camera->width(), camera->height(), *rgb);
  if (!written.ok()) return report_command_error("render", written.message());
  if (!args.quiet) {
    const std::string where = args.server.empty() ? "in process" : "by " + args.server;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    std::fprintf(stderr,
                 "outcore render: %llu rays (%llu hit) traced in %.3f s = %.2f M rays/s %s; %ux%u %s image "
                 "written to %s (%.3f s in all)\n",
                 static_cast<unsigned long long>(report.rays), static_cast<unsigned long long>(report.hits),
                 report.trace_seconds, report.rays / std::max(report.trace_seconds, 1e-9) / 1e6,
                 where.c_str(), camera->width(), camera->height(), render_mode_name(*mode),
                 args.output_path.c_str(), seconds);
  }
  return 0;
}

void add_engine_options(CLI::App& group, RenderArgs& args) {
  add_cache_options(group, args.engine);
  group.add_option("--accel-opt", args.engine.accel_options, "Brick structure option key=value (repeatable)");
  group.add_option("--triangle-test", args.engine.triangle_test,
                   "Triangle test of the brick structure: mt, watertight (default) or double");
  group.add_flag("--reference", args.engine.reference, "Float64 brute force per brick (slow ground truth)");
  group.add_flag("--no-proxies", args.engine.no_proxies, "Do not skip bricks by their occupancy proxies");
  group.add_option("--proxy-res", args.engine.proxy_res, "Proxy voxels along each brick's longest side");
  group.add_option("--threads", args.threads, "Worker threads (0, the default: all cores)")
      ->check(CLI::Range(0, kMaxThreadsOption));
}

}  // namespace

void add_render_command(CLI::App& app, int& exit_code, ConnectRenderServer connect) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render a picture of a scene (depth, normals or ids) through Open3D's pinhole camera");
  cmd->add_option("store", args->store, "Scene store directory (or --server)");
  cmd->add_option("--eye", args->eye, "Camera position X,Y,Z")->required();
  cmd->add_option("--center", args->center, "Point looked at X,Y,Z")->required();
  cmd->add_option("--up", args->up,
                  "The world's up X,Y,Z: the picture is upright (the rays are Open3D's "
                  "create_rays_pinhole with -up, whose rows run along its up)")
      ->required();
  cmd->add_option("--fov", args->fov_deg, "Horizontal field of view, degrees, in (0, 180)")->required();
  cmd->add_option("--size", args->size, "Image size WIDTHxHEIGHT in pixels, e.g. 640x480")->required();
  cmd->add_option("-o,--output", args->output_path, "PNG to write (replaced atomically)")->required();
  cmd->add_option("--mode", args->mode, "depth (near bright), normals or ids (a colour per input)")
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", args->quiet, "No progress or timing lines on stderr");
  OptionGroups groups;
  groups.engine = cmd->add_option_group("In-process engine (with STORE)");
  add_engine_options(*groups.engine, *args);
  groups.server = cmd->add_option_group("Server (with --server)");
  // --server itself is not in the group: it is what chooses the path.
  cmd->add_option("--server", args->server, "HOST:PORT of an `outcore serve` server (instead of STORE)");
  groups.server->add_option("--deadline-s", args->deadline_seconds,
                            "Deadline of each call (a band of up to 4 Mi rays), seconds (0: none)");
  groups.server->add_flag("--no-shared-memory", args->no_shared_memory,
                          "Send rays and get hits over gRPC even when the server is on this host");
  groups.server->add_option("--tls-ca", args->tls_ca,
                            "Connect with TLS, trusting this CA's certificate (PEM)");
  groups.server->add_option("--tls-cert", args->tls_cert,
                            "Client certificate for servers that require one (PEM)");
  groups.server->add_option("--tls-key", args->tls_key, "The client certificate's private key (PEM)");
  groups.server->add_option("--auth-token-file", args->auth_token_file,
                            "Send this file's token on every call (authorization: Bearer TOKEN)");
  cmd->callback([args, groups, connect = std::move(connect), &exit_code] {
    exit_code = run_render(*args, groups, connect);
  });
}

}  // namespace outcore
