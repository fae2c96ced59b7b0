#include "client/cli/query_command.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/channel_options.h"
#include "client/cpp/replica_router.h"
#include "client/cpp/scene_client.h"
#include "core/cli/commands.h"
#include "core/io/npy.h"
#include "core/query/query_engine.h"

namespace outcore {

namespace {

struct QueryArgs {
  std::string server = "127.0.0.1:50051";
  std::string rays_path;
  std::string output_path;
  bool any_hit = false;
  double deadline_seconds = 0;
  bool strict = false;
  bool no_reorder = false;
  uint64_t chunk_rays = 0;
  bool print_stats = false;
  bool no_shared_memory = false;
  int repeat = 1;
  ChannelSecurityArgs security;
  bool quiet = false;
  std::string hit_fields = "all";
  std::string routing = "bricks";
};

int run_query(const QueryArgs& args) {
  // NaN compares false both ways: it would pass a plain `< 0` test as "no deadline".
  if (!std::isfinite(args.deadline_seconds) || args.deadline_seconds < 0) {
    char given[32];
    std::snprintf(given, sizeof(given), "%g", args.deadline_seconds);
    return report_command_error("query",
                                std::string("--deadline-s must be a number >= 0 (0: none), got ") + given);
  }
  auto rays = read_rays_npy(args.rays_path);
  if (!rays.ok()) return report_command_error("query", rays.status().message());
  client::ConnectOptions connect_options;
  if (args.deadline_seconds > 0) connect_options.timeout_seconds = args.deadline_seconds;
  connect_options.shared_memory = !args.no_shared_memory;
  auto security = channel_security_of(args.security);
  if (!security.ok()) return report_command_error("query", security.status().message());
  connect_options.security = std::move(*security);
  // "a:1,b:2,c:3": replicas, each batch routed across them (replica_router.h).
  const auto replicas_or = client::replica_list(args.server);
  if (!replicas_or.ok()) return report_command_error("query", replicas_or.status().message());
  const std::vector<std::string>& replicas = *replicas_or;
  std::unique_ptr<client::SceneClient> single;
  std::unique_ptr<client::ReplicaRouter> router;
  if (replicas.empty()) {
    auto connection = client::SceneClient::connect(args.server, connect_options);
    if (!connection.ok()) return report_command_error("query", connection.status().message());
    single = std::move(*connection);
  } else {
    // A dns: name is resolved again every 30 s (pods come and go).
    auto connection = args.server.starts_with("dns:")
                          ? client::ReplicaRouter::connect_dns(args.server, connect_options)
                          : client::ReplicaRouter::connect(replicas, connect_options);
    if (!connection.ok()) return report_command_error("query", connection.status().message());
    router = std::move(*connection);
    if (args.routing == "rays") router->set_routing(client::ReplicaRouting::kRays);
    if (args.routing == "bricks" && router->routing() != client::ReplicaRouting::kBricks) {
      return report_command_error("query",
                                  "--routing bricks: the replicas do not list their bricks (a server before "
                                  "SceneInfo.bricks); use --routing rays");
    }
  }

  client::CallOptions options;
  options.deadline_seconds = args.deadline_seconds;
  options.strict = args.strict;
  options.no_reorder = args.no_reorder;
  options.chunk_rays = args.chunk_rays;
  options.hit_fields = args.hit_fields == "t"       ? v1::HIT_FIELDS_T
                       : args.hit_fields == "t,ids" ? v1::HIT_FIELDS_T_IDS
                                                    : v1::HIT_FIELDS_ALL;
  ProgressStyle style;
  style.show_after = kShowProgressAfter;
  ProgressBar progress("query", rays->size() * static_cast<uint64_t>(std::max(1, args.repeat)), "rays",
                       !args.quiet, stderr, std::move(style));
  ProgressTicker ticker(progress);
  options.progress = &progress;
  client::CallStats stats;
  Status status;
  Status written;
  std::vector<uint8_t> occluded(args.any_hit ? rays->size() : 0);
  std::vector<Hit> hits(args.any_hit ? 0 : rays->size());
  // Repeats send the same batch again (for benchmarks: the wall time of each
  // whole call, client chunking and wire included, file I/O excluded); the
  // output and --stats are the last call's.
  for (int r = 0; r < std::max(1, args.repeat) && status.ok(); ++r) {
    stats = client::CallStats{};
    const auto start = std::chrono::steady_clock::now();
    if (router) {
      status = args.any_hit ? router->occluded(*rays, occluded, options, &stats)
                            : router->intersect(*rays, hits, options, &stats);
    } else {
      status = args.any_hit ? single->occluded(*rays, occluded, options, &stats)
                            : single->intersect(*rays, hits, options, &stats);
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (args.repeat > 1 && status.ok()) std::printf("call %d/%d seconds %.6f\n", r + 1, args.repeat, seconds);
  }
  progress.finish();
  if (status.ok()) {
    written =
        args.any_hit ? write_bools_npy(args.output_path, occluded) : write_hits_npy(args.output_path, hits);
  }
  if (!status.ok()) return report_command_error("query", status.message());
  if (!written.ok()) return report_command_error("query", written.message());
  if (args.print_stats) {
    // Printed as `outcore trace --stats` does; the cache's peak and budget
    // and the proxies' size are server-wide, so they come from GetStats.
    // With replicas the figures are summed over them, the server-wide ones
    // left out (each replica has its own: ask each with GetStats).
    QueryStats s = client::to_query_stats(stats.engine);
    if (single) {
      auto server = single->stats(args.deadline_seconds);
      if (!server.ok()) return report_command_error("query", server.status().message());
      s.peak_bytes_resident = server->peak_resident_bytes();
      s.cache_budget_bytes = server->cache_budget_bytes();
      s.proxy_bytes = server->proxy_bytes();
    }
    std::printf("messages %llu\n", static_cast<unsigned long long>(stats.messages));
    std::printf("shared_memory %s\n", stats.shared ? "yes" : "no");
    std::fputs(s.to_text().c_str(), stdout);
  }
  return 0;
}

}  // namespace

void add_query_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<QueryArgs>();
  CLI::App* cmd = app.add_subcommand("query", "Trace a rays .npy on an `outcore serve` server");
  cmd->add_option("--server", args->server,
                  "HOST:PORT of the server, or replicas HOST:PORT,HOST:PORT,... or dns:///NAME:PORT "
                  "(docs/SCALING.md)")
      ->capture_default_str();
  cmd->add_option("--rays", args->rays_path, "Rays .npy: float32 (N,6) or (N,8)")->required();
  cmd->add_option("-o,--output", args->output_path, "Hits .npy to write (bool .npy with --any-hit)")
      ->required();
  cmd->add_flag("--any-hit", args->any_hit, "Occlusion query: write whether each ray hits anything");
  cmd->add_option("--deadline-s", args->deadline_seconds, "Deadline of the whole batch, seconds (0: none)");
  cmd->add_flag("--strict", args->strict, "Invalid rays are an error naming the first one (default: misses)");
  cmd->add_flag("--no-reorder", args->no_reorder, "Server traces rays one by one in input order");
  cmd->add_option(
         "--chunk-rays", args->chunk_rays,
         "Rays per message (default: as many as the server's max message size allows); larger batches "
         "are streamed")
      ->check(CLI::Range(uint64_t{0}, uint64_t{1} << 40));
  cmd->add_flag("--no-shared-memory", args->no_shared_memory,
                "Send rays and get hits over gRPC even when the server is on this host (default: batches "
                "of 16,384 rays or more go through shared memory then)");
  cmd->add_flag("--stats", args->print_stats,
                "Print the engine's figures summed over the replies (as trace --stats)");
  cmd->add_option("--repeat", args->repeat,
                  "Send the batch this many times, printing each call's wall seconds")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  add_channel_security_options(*cmd, args->security);
  cmd->add_flag("-q,--quiet", args->quiet, "No progress line on stderr (shown for calls over 2 s)");
  cmd->add_option(
         "--hit-fields", args->hit_fields,
         "Hit fields the replies carry over the bytes path: all (32 bytes a ray), t (4) or t,ids (12); "
         "the others are written as a miss's (ids 4294967295, u = v = 0, zero normal)")
      ->check(CLI::IsMember({"all", "t", "t,ids"}))
      ->capture_default_str();
  cmd->add_option("--routing", args->routing,
                  "With replicas: bricks (each replica owns a part of the bricks and traces every ray in it; "
                  "the nearest answer is kept: each brick built on one replica) or rays (each ray to one "
                  "replica by the cell where it enters the scene)")
      ->check(CLI::IsMember({"bricks", "rays"}))
      ->capture_default_str();
  cmd->callback([args, &exit_code] { exit_code = run_query(*args); });
}

}  // namespace outcore
