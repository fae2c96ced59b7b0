#include "server/serve_command.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/cli/commands.h"
#include "core/cli/engine_options_cli.h"
#include "core/io/bearer_token_file.h"
#include "core/query/query_engine.h"
#include "core/util/cancellation.h"
#include "core/util/loopback_address.h"
#include "server/json_log_formatter.h"
#include "server/metrics_http_server.h"
#include "server/rpc_metrics.h"
#include "server/scene_query_service.h"
#include "server/server_security.h"
#include "server/throughput_history.h"

namespace outcore {

namespace {

// Once the drain bound has passed and in-flight batches were cancelled, calls
// get this long to end before the process exits without them: a cancelled
// batch stops at its next brick, well within it.
constexpr std::chrono::seconds kCancelGrace{1};
// While serving, a summary is logged at most this often (when anything changed).
constexpr std::chrono::seconds kSummaryInterval{60};

struct ServeArgs {
  std::string scene;
  std::string listen = "127.0.0.1:50051";
  EngineCliOptions engine;
  int threads = 0;
  int rpc_threads = 64;
  uint32_t max_message_mb = 64;
  int64_t stream_group_rays = 0;  // 0: automatic
  int64_t stream_gather_ms = -1;  // negative: automatic
  bool no_shared_payloads = false;
  std::string log_level = "info";
  std::string log_format = "text";
  std::string metrics_listen;  // empty: no metrics endpoint
  server::TlsFiles tls;
  std::string auth_token_file;
  bool insecure = false;  // plaintext on a non-loopback address is allowed
  double drain_s = 10;    // in-flight calls' time to finish after SIGINT/SIGTERM
};

void log_summary(const server::SceneQueryService& service, const QueryEngine& engine) {
  const server::ServiceCounters c = service.counters();
  const CacheCounters cache = engine.cache().counters();
  spdlog::info(
      "{} requests ({} failed, {} cancelled), {} rays ({} hit, {} invalid), {:.3f} s tracing; cache: {} "
      "hits, "
      "{} misses, {} builds, {} evictions, {} bricks / {} bytes resident (peak {}, budget {})",
      c.requests, c.failed_requests, c.cancelled_requests, c.answered.rays, c.answered.rays_hit,
      c.answered.invalid_rays, c.answered.seconds_total, cache.hits, cache.misses, cache.builds,
      cache.evictions, cache.resident_bricks, cache.resident_bytes, cache.peak_resident_bytes,
      engine.cache().budget_bytes());
  if (engine.cache().subtree_tier() != nullptr) {
    const SubtreeTierCounters& t = cache.subtree;
    spdlog::info("subtree tier: {} loads ({:.3f} s), {} writes, {} rejected, {} files / {} bytes on disk",
                 t.loads, t.load_seconds, t.writes, t.rejected(), t.files, t.bytes);
  }
}

// Serves until SIGINT or SIGTERM (returned): once a second checks whether the
// store was replaced on disk, and logs a summary at most every
// kSummaryInterval when requests came in; records the rays answered each
// second for the status page's recent throughput.
int serve_until_stop_signal(const sigset_t& stop_signals, server::SceneQueryService& service,
                            const QueryEngine& engine, server::ThroughputHistory& throughput) {
  int signal_number = 0;
  auto last_summary = std::chrono::steady_clock::now();
  uint64_t requests_at_summary = 0;
  while (signal_number <= 0) {
    const timespec tick{1, 0};
    signal_number = sigtimedwait(&stop_signals, nullptr, &tick);
    if (signal_number <= 0) service.check_store();
    const auto now = std::chrono::steady_clock::now();
    throughput.record(now, service.counters().answered.rays);
    if (signal_number <= 0 && now - last_summary >= kSummaryInterval) {
      const uint64_t requests = service.counters().requests;
      if (requests != requests_at_summary) log_summary(service, engine);
      requests_at_summary = requests;
      last_summary = now;
    }
  }
  return signal_number;
}

// Stops `grpc_server` after SIGINT/SIGTERM: in-flight calls get `drain_s` seconds
// to finish, then their batches are cancelled, and past kCancelGrace the
// process exits with status 1 without them.
void drain_and_stop(grpc::Server& grpc_server, double drain_s, const server::SceneQueryService& service,
                    const QueryEngine& engine) {
  const auto drain =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::duration<double>(drain_s));
  grpc_server.GetHealthCheckService()->Shutdown();  // NOT_SERVING from now on
  // gRPC cancels the calls still running at the deadline, but waits for their
  // handlers to return, and a handler inside the engine returns only when its
  // batch ends. So this thread watches the bound: past it, the engine's
  // batches are cancelled, and past the grace the process exits regardless.
  const auto drain_end = std::chrono::steady_clock::now() + drain;
  std::mutex stop_mutex;
  std::condition_variable stop_done;
  bool stopped = false;
  std::thread stopper([&] {
    grpc_server.Shutdown(std::chrono::system_clock::now() + drain);
    grpc_server.Wait();
    std::lock_guard lock(stop_mutex);
    stopped = true;
    stop_done.notify_all();
  });
  {
    std::unique_lock lock(stop_mutex);
    if (!stop_done.wait_until(lock, drain_end, [&] { return stopped; })) {
      spdlog::warn("drain bound of {} s passed with calls in flight: cancelling their batches", drain_s);
      request_cancel();
      if (!stop_done.wait_until(lock, drain_end + kCancelGrace, [&] { return stopped; })) {
        log_summary(service, engine);
        spdlog::error("calls still running {} s after the drain bound; exiting without them",
                      kCancelGrace.count());
        spdlog::default_logger()->flush();
        std::fflush(nullptr);
        std::_Exit(1);
      }
    }
  }
  stopper.join();
}

// The serving options' checks (the engine's, --cache-mb included, are
// apply_engine_options').
Status check_serve_args(const ServeArgs& args) {
  // gRPC takes message limits as int.
  if (args.max_message_mb == 0 || args.max_message_mb > 2047) {
    return invalid_argument("--max-message-mb must be between 1 and 2047, got " +
                            std::to_string(args.max_message_mb));
  }
  if (args.threads < 0) return invalid_argument("--threads must be >= 0 (0: all cores)");
  if (args.stream_group_rays < 0) return invalid_argument("--stream-group-rays must be >= 0 (0: automatic)");
  if (args.stream_gather_ms > 60'000) {
    return invalid_argument("--stream-gather-ms must be at most 60000 (-1: automatic)");
  }
  if (args.rpc_threads < 2) return invalid_argument("--rpc-threads must be at least 2");
  if (!(args.drain_s > 0 && args.drain_s <= 3600)) {
    return invalid_argument("--drain-s must be more than 0 and at most 3600, got " +
                            std::to_string(args.drain_s));
  }
  // Unix sockets have no port; gRPC checks their paths.
  const bool unix_socket = args.listen.starts_with("unix:") || args.listen.starts_with("unix-abstract:");
  if (!unix_socket) {
    const auto port = port_of(args.listen, 0);
    if (!port.ok()) return invalid_argument("--listen " + port.status().message());
  }
  return server::check_listen_exposure(args.listen, args.tls.enabled(), args.insecure);
}

void log_engine(const QueryEngine& engine, const EngineOptions& engine_options) {
  spdlog::info("brick structure: {} ({}){}", engine_options.brick_accel,
               describe_accel_options(engine.accel_options()),
               engine.cache_fits_scene() ? "" : "; the budget cannot hold the scene: trace-ahead on");
  if (const ProxySet* proxies = engine.proxies()) {
    const ProxyOpenReport& report = engine.proxy_report();
    spdlog::info("brick proxies: resolution {}, {} bricks, {} bytes resident, {} in {:.3f} s",
                 proxies->config().resolution, proxies->brick_count(), proxies->memory_bytes(),
                 report.loaded ? "loaded from proxies.bin" : (report.written ? "built and written" : "built"),
                 report.seconds);
  } else {
    spdlog::info("brick proxies off");
  }
}

Expected<server::ServiceOptions> service_options_of(const ServeArgs& args) {
  server::ServiceOptions service_options;
  if (!args.auth_token_file.empty()) {
    auto token = read_bearer_token_file(args.auth_token_file);
    if (!token.ok()) return token.status().with_context("--auth-token-file");
    service_options.auth_token = std::move(*token);
  }
  service_options.max_message_bytes = uint64_t{args.max_message_mb} << 20;
  service_options.max_group_rays = static_cast<uint64_t>(args.stream_group_rays);
  service_options.gather_wait_ms = args.stream_gather_ms;
  service_options.shared_payloads = !args.no_shared_payloads;
  return service_options;
}

// The gRPC server with `service` registered, listening (null when it cannot
// listen); *port is the port it listens on. Every call ends in `rpc_metrics`.
std::unique_ptr<grpc::Server> start_grpc_server(const ServeArgs& args, server::SceneQueryService& service,
                                                const std::shared_ptr<grpc::ServerCredentials>& credentials,
                                                server::RpcMetrics& rpc_metrics, uint64_t max_message_bytes,
                                                int* port) {
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(args.listen, credentials, port);
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(std::make_unique<server::RpcMetricsInterceptorFactory>(rpc_metrics));
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  // gRPC sets SO_REUSEPORT by default: a second server on a taken port would
  // silently share it. A busy port is an error instead.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.SetMaxReceiveMessageSize(static_cast<int>(max_message_bytes));
  builder.SetMaxSendMessageSize(static_cast<int>(max_message_bytes));
  // The sync server runs each call on a thread of its own; the quota bounds
  // them (calls beyond it wait for a thread).
  grpc::ResourceQuota quota("outcore-serve");
  quota.SetMaxThreads(args.rpc_threads);
  builder.SetResourceQuota(quota);
  builder.RegisterService(&service);
  return builder.BuildAndStart();
}

// The metrics endpoint when --metrics-listen is given (else null), its
// address printed as "metrics on http://HOST:PORT" before "listening on".
Expected<std::unique_ptr<server::MetricsHttpServer>> start_metrics(
    const ServeArgs& args, const server::SceneQueryService& service, const QueryEngine& engine,
    const server::RpcMetrics& rpc_metrics, const server::ThroughputHistory& throughput,
    const std::string& address) {
  if (args.metrics_listen.empty()) return std::unique_ptr<server::MetricsHttpServer>();
  server::ServerIdentity identity;
  identity.scene = args.scene;
  identity.address = address;
  identity.brick_structure = engine.cache().builder().name();
  identity.eviction_policy = engine.cache().policy().name();
  identity.triangles = engine.store().manifest().triangle_count;
  identity.bricks = engine.store().brick_count();
  identity.tls = args.tls.enabled();
  identity.token = !args.auth_token_file.empty();
  identity.version = OUTCORE_VERSION;
  const auto started = std::chrono::steady_clock::now();
  auto collect = [&service, &engine, &rpc_metrics, started] {
    const double uptime = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    return server::collect_metrics(service, engine, rpc_metrics, uptime);
  };
  OUTCORE_ASSIGN_OR_RETURN(
      auto metrics, server::MetricsHttpServer::start(args.metrics_listen, collect, identity, throughput));
  std::printf("metrics on http://%s\n", metrics->address().c_str());
  if (!is_loopback_host(host_of(args.metrics_listen))) {
    spdlog::warn(
        "--metrics-listen {} is not a loopback address: /metrics and the status page have no TLS or "
        "token; keep that port on a network only the scraper reaches",
        args.metrics_listen);
  }
  spdlog::info("metrics at http://{}/metrics, status page at http://{}/", metrics->address(),
               metrics->address());
  return metrics;
}

int run_serve(const ServeArgs& args) {
  // Signals are taken synchronously by this thread (sigtimedwait below), so
  // every thread started from here on (gRPC, TBB) inherits them blocked.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  auto logger = args.log_format == "json" ? spdlog::stderr_logger_mt("outcore-serve")
                                          : spdlog::stderr_color_mt("outcore-serve");
  if (args.log_format == "json") logger->set_formatter(std::make_unique<server::JsonLogFormatter>());
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(args.log_level));

  const Status checked = check_serve_args(args);
  if (!checked.ok()) return report_command_error("serve", checked.message());
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0) {
    threads =
        std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, args.threads);
  }
  EngineOptions engine_options;
  const Status options = apply_engine_options(args.engine, engine_options);
  if (!options.ok()) return report_command_error("serve", options.message());
  auto engine = QueryEngine::open(args.scene, engine_options);
  if (!engine.ok()) return report_command_error("serve", engine.status().message());
  log_engine(**engine, engine_options);

  const auto service_options = service_options_of(args);
  if (!service_options.ok()) return report_command_error("serve", service_options.status().message());
  const auto credentials = server::server_credentials(args.tls);
  if (!credentials.ok()) return report_command_error("serve", credentials.status().message());
  server::SceneQueryService service(**engine, *service_options);
  server::RpcMetrics rpc_metrics;
  int port = 0;
  std::unique_ptr<grpc::Server> server =
      start_grpc_server(args, service, *credentials, rpc_metrics, service_options->max_message_bytes, &port);
  if (!server || port == 0) return report_command_error("serve", "cannot listen on " + args.listen);
  // The health service answers SERVING from here on (the scene is open), for
  // the server as a whole ("") and for the service by name.
  server->GetHealthCheckService()->SetServingStatus(v1::SceneQuery::service_full_name(), true);
  const std::string address = args.listen.substr(0, args.listen.rfind(':')) + ":" + std::to_string(port);
  server::ThroughputHistory throughput;
  auto metrics = start_metrics(args, service, **engine, rpc_metrics, throughput, address);
  if (!metrics.ok()) return report_command_error("serve", metrics.status().message());
  std::printf("listening on %s\n", address.c_str());
  std::fflush(stdout);
  const Manifest& manifest = (*engine)->store().manifest();
  spdlog::info("serving {} ({} triangles, {} bricks, cache budget {} MiB) on {}", args.scene,
               manifest.triangle_count, (*engine)->store().brick_count(), args.engine.cache_mb, address);

  const int signal_number = serve_until_stop_signal(stop_signals, service, **engine, throughput);
  spdlog::info("signal {}: draining in-flight calls (at most {} s)", signal_number, args.drain_s);
  drain_and_stop(*server, args.drain_s, service, **engine);
  metrics->reset();
  log_summary(service, **engine);
  spdlog::info("stopped");
  return 0;
}

}  // namespace

void add_serve_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<ServeArgs>();
  CLI::App* cmd = app.add_subcommand("serve", "Answer ray queries against a scene store over gRPC");
  cmd->add_option("scene", args->scene, "Scene store directory")->required();
  cmd->add_option("--listen", args->listen, "HOST:PORT to listen on (port 0: any free port)")
      ->capture_default_str();
  add_cache_options(*cmd, args->engine);
  cmd->add_flag("--no-proxies", args->engine.no_proxies, "Do not skip bricks by their occupancy proxies");
  cmd->add_option("--proxy-res", args->engine.proxy_res,
                  "Proxy voxels along each brick's longest side (default 32)");
  cmd->add_option("--threads", args->threads, "Engine worker threads (default: all cores)")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--rpc-threads", args->rpc_threads, "Most threads serving calls at once")
      ->check(CLI::Range(2, 65536))
      ->capture_default_str();
  cmd->add_option("--max-message-mb", args->max_message_mb, "Largest message either way, MiB")
      ->capture_default_str();
  cmd->add_option("--stream-group-rays", args->stream_group_rays,
                  "Most rays of a stream traced in one engine call (chunks that queued up while the "
                  "engine was busy are traced together); 0: 1024 per brick of the store")
      ->check(CLI::Range(int64_t{0}, std::numeric_limits<int64_t>::max()))
      ->capture_default_str();
  cmd->add_option("--stream-gather-ms", args->stream_gather_ms,
                  "Before tracing, wait for a stream's chunks while they come at most this many ms apart, "
                  "up to --stream-group-rays; -1: 50 when the cache cannot hold the scene, else 0")
      ->check(CLI::Range(int64_t{-1}, int64_t{60'000}))
      ->capture_default_str();
  cmd->add_flag("--no-shared-payloads", args->no_shared_payloads,
                "Refuse shared-memory payloads (same-host clients then send rays and get hits over gRPC)");
  cmd->add_option("--drain-s", args->drain_s,
                  "After SIGINT/SIGTERM, seconds in-flight calls get to finish before they are cancelled")
      ->capture_default_str();
  cmd->add_option("--log-level", args->log_level, "Log level")
      ->check(CLI::IsMember({"debug", "info", "warn"}))
      ->capture_default_str();
  cmd->add_option("--log-format", args->log_format, "Log lines as text, or as one JSON object each")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  cmd->add_option("--metrics-listen", args->metrics_listen,
                  "HOST:PORT for Prometheus metrics (/metrics) and a status page (/); port 0: any free port");
  cmd->add_option("--tls-cert", args->tls.cert,
                  "Serve TLS with this certificate chain (PEM; needs --tls-key)");
  cmd->add_option("--tls-key", args->tls.key, "The TLS certificate's private key (PEM)");
  cmd->add_option("--tls-client-ca", args->tls.client_ca,
                  "Require client certificates signed by this CA (PEM; mutual TLS)");
  cmd->add_option(
      "--auth-token-file", args->auth_token_file,
      "Require every call to carry this file's token (authorization: Bearer TOKEN); health exempt");
  cmd->add_flag("--insecure", args->insecure,
                "Allow plaintext on a non-loopback --listen address (refused without TLS otherwise)");
  cmd->callback([args, &exit_code] { exit_code = run_serve(*args); });
}

}  // namespace outcore
