#include "server/metrics_http_server.h"

#include <httplib.h>
#include <spdlog/spdlog.h>

#include "core/util/loopback_address.h"
#include "server/status_page.h"

namespace outcore::server {

namespace {

// A scrape is a few kilobytes built in microseconds: two threads keep a
// scraper and a person's browser from waiting on each other without taking
// cores from tracing.
constexpr std::size_t kHttpThreads = 2;

}  // namespace

Expected<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::start(const std::string& host_port,
                                                                      Collect collect,
                                                                      ServerIdentity identity,
                                                                      const ThroughputHistory& history) {
  const Expected<uint16_t> parsed_port = port_of(host_port, 0);
  if (!parsed_port.ok()) return invalid_argument("--metrics-listen " + parsed_port.status().message());
  const uint16_t port = *parsed_port;
  const std::string host(host_of(host_port));
  std::unique_ptr<MetricsHttpServer> server(new MetricsHttpServer());
  server->http_ = std::make_unique<httplib::Server>();
  httplib::Server& http = *server->http_;
  http.new_task_queue = [] { return new httplib::ThreadPool(kHttpThreads); };
  http.Get("/metrics", [collect, identity](const httplib::Request&, httplib::Response& response) {
    response.set_content(prometheus_text(collect(), identity), "text/plain; version=0.0.4; charset=utf-8");
  });
  http.Get("/", [collect, identity, &history](const httplib::Request&, httplib::Response& response) {
    RecentThroughput recent;
    recent.rays_per_second_10s = history.rays_per_second(std::chrono::seconds(10));
    recent.rays_per_second_60s = history.rays_per_second(std::chrono::seconds(60));
    response.set_content(status_page_html(collect(), identity, recent), "text/html; charset=utf-8");
  });
  const int bound = port == 0 ? http.bind_to_any_port(host) : (http.bind_to_port(host, port) ? port : -1);
  if (bound <= 0) {
    return io_error("--metrics-listen " + host_port +
                    ": cannot listen there (port in use, or not this host's address)");
  }
  const bool bracketed = host.find(':') != std::string::npos;
  server->address_ = (bracketed ? "[" + host + "]" : host) + ":" + std::to_string(bound);
  server->thread_ = std::thread([&http] {
    if (!http.listen_after_bind()) spdlog::error("metrics server stopped unexpectedly");
  });
  return server;
}

MetricsHttpServer::~MetricsHttpServer() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace outcore::server
